"""`ros2py`: the ros2 command-line verbs we need, for machines without ROS 2's `ros2`.

    ros2py topic list|echo|hz|bw|info|pub     ros2py node list|info     ros2py service list|call
    ros2py param get|set|dump|list|load|describe    ros2py bag record|play|info    ros2py run PKG EXE
    ros2py tf echo TARGET SOURCE           ros2py interface show TYPE
    ros2py action list|info|send_goal      ros2py lifecycle nodes|get|list|set
    ros2py control list_controllers|list_hardware_components|list_hardware_interfaces|
                   switch_controllers|load_controller|set_controller_state|unload_controller

Only argparse is imported up front; each verb imports rclpy and its modules when it runs,
so `ros2py topic echo` starts quickly. Failures print one line and exit 1 (Ctrl-C exits 0); bad
arguments (argparse's refusals, invalid names) print one line and exit 2.
rclpy's teardown comes after the output and may take TEARDOWN_DEADLINE_S: a command that has
done its work ends then with its own exit code, even when the teardown never returns.
"""
from __future__ import annotations

import argparse
import gc
import importlib
import math
import os
import signal
import sys
from typing import Callable, List, Optional

PROG = "ros2py"
QOS_RELIABILITY = ["reliable", "best_effort", "system_default"]
QOS_DURABILITY = ["volatile", "transient_local", "system_default"]
# listing waits until the graph is unchanged for 2 s (session.SETTLE_S); on a busy machine
# the last node can appear about 3 s after start, so the bound is above 3 + 2 s
LIST_SPIN_TIME_S = 6.0
WAIT_FOR_NODE_S = 5.0  # discovering a node or topic can take 2-3 s on a loaded machine
MAX_CACHE_BYTES = 100 * 1024 * 1024  # bag record: rosbag2's default --max-cache-size (about 110 VGA frames)
# rclpy's teardown (executor, node, context, DDS participant) takes 10-30 ms here; rclpy 7.1.6
# can hang in Node.destroy_node for many minutes. Past this, the process ends with the command's
# exit code.
TEARDOWN_DEADLINE_S = 2.0
CLOCK_MONOTONIC = 1  # <time.h>
SIGEV_THREAD = 2  # <signal.h>: on expiry, call a function in a new thread


class _Parser(argparse.ArgumentParser):
    """argparse's refusals as one line `ros2py: <what is wrong>` (exit code 2), like every other failure."""

    def error(self, message: str):
        self.exit(2, f"{PROG}: {message} (see `{self.prog} -h`)\n")


def _number(convert, text: str, fits, expected: str):
    try:
        value = convert(text)
    except ValueError:
        value = None
    if value is None or not math.isfinite(value) or not fits(value):
        raise argparse.ArgumentTypeError(f"expected {expected}, got '{text}'")
    return value


# argparse types of every numeric option: a negative timeout, count or duration is refused
# before the verb runs, instead of being waited, counted or recorded as if it meant something
def positive_float(text: str) -> float:
    """Seconds, rates: a finite number > 0."""
    return _number(float, text, lambda v: v > 0, "a number > 0")


def non_negative_float(text: str) -> float:
    """Delays, offsets: a finite number >= 0."""
    return _number(float, text, lambda v: v >= 0, "a number >= 0")


def positive_int(text: str) -> int:
    """Counts of at least one (window, queue depth, times to print)."""
    return _number(int, text, lambda v: v > 0, "an integer > 0")


def non_negative_int(text: str) -> int:
    """Counts where 0 means none or no limit (times, byte sizes)."""
    return _number(int, text, lambda v: v >= 0, "an integer >= 0")


def _verb(subparsers, name: str, target: str, help: str):
    """A sub-command whose handler is `module:function` in ball_balance.cli (imported lazily)."""
    parser = subparsers.add_parser(name, help=help, description=help)
    parser.set_defaults(_target=target)
    return parser


def _spin_time(parser, default: float = 3.0) -> None:
    parser.add_argument("--spin-time", type=non_negative_float, default=default,
                        help="seconds to wait for discovery (default: %(default)s)")


def _qos(parser, depth_default: int = 10) -> None:
    parser.add_argument("--qos-reliability", choices=QOS_RELIABILITY, help="override the QoS reliability")
    parser.add_argument("--qos-durability", choices=QOS_DURABILITY, help="override the QoS durability")
    parser.add_argument("--qos-depth", type=positive_int, default=depth_default,
                        help="queue depth (default: %(default)s)")


def _list_options(p, noun: str) -> None:
    """The options `ros2 topic list` and `ros2 service list` share (-t, -c, hidden ones)."""
    p.add_argument("-t", "--show-types", action="store_true", help=f"additionally show the {noun} type")
    p.add_argument("-c", f"--count-{noun}s", action="store_true", help=f"only show the number of {noun}s")
    p.add_argument(f"--include-hidden-{noun}s", action="store_true", help=f"consider hidden {noun}s as well")
    _spin_time(p, LIST_SPIN_TIME_S)


def _watch_options(p, window_default: int) -> None:
    """What `topic hz` and `topic bw` take: a topic, a window, a duration, the QoS."""
    p.add_argument("topic_name")
    p.add_argument("--window", "-w", type=positive_int, default=window_default,
                   help="window size in messages (default: %(default)s)")
    p.add_argument("--duration", type=positive_float, default=None,
                   help="ros2py extension: stop after this many seconds")
    _qos(p)
    _spin_time(p, WAIT_FOR_NODE_S)


def _topic_parsers(sub) -> None:
    topic = sub.add_parser("topic", help="inspect and publish topics").add_subparsers(dest="verb", required=True)
    _list_options(_verb(topic, "list", "topic:cmd_list", "output a list of available topics"), "topic")

    p = _verb(topic, "echo", "topic:cmd_echo", "output messages from a topic")
    p.add_argument("topic_name", help="name of the topic, e.g. /ball_state")
    p.add_argument("message_type", nargs="?", help="type of the message (default: from the graph)")
    p.add_argument("--once", action="store_true", help="print the first message received and exit")
    p.add_argument("--field", help="echo only this field, e.g. header.stamp")
    p.add_argument("--truncate-length", type=non_negative_int, default=128,
                   help="truncate arrays/strings (default: 128)")
    p.add_argument("--full-length", "-f", action="store_true", help="do not truncate arrays or strings")
    p.add_argument("--no-arr", action="store_true", help="do not print array fields")
    p.add_argument("--no-str", action="store_true", help="do not print string fields")
    p.add_argument("--timeout", type=positive_float, default=None,
                   help="ros2py extension: give up after this many seconds without a message")
    _qos(p)
    _spin_time(p, WAIT_FOR_NODE_S)

    _watch_options(_verb(topic, "hz", "topic:cmd_hz", "print the average receiving rate of a topic"), 10000)
    _watch_options(_verb(topic, "bw", "topic:cmd_bw", "display the bandwidth used by a topic"), 100)

    p = _verb(topic, "info", "topic:cmd_info", "print information about a topic")
    p.add_argument("topic_name")
    p.add_argument("--verbose", "-v", action="store_true", help="print node, QoS and GID of each endpoint")
    _spin_time(p, WAIT_FOR_NODE_S)

    p = _verb(topic, "pub", "topic:cmd_pub", "publish a message to a topic")
    p.add_argument("topic_name")
    p.add_argument("message_type", help="e.g. std_msgs/msg/String")
    p.add_argument("values", nargs="?", default="{}", help="message values in YAML, e.g. \"{data: hi}\"")
    p.add_argument("-r", "--rate", type=positive_float, default=1.0, help="publishing rate in Hz (default: 1)")
    p.add_argument("-1", "--once", action="store_true", help="publish one message and exit")
    p.add_argument("-t", "--times", type=non_negative_int, default=0, help="publish this many messages and exit")
    p.add_argument("-w", "--wait-matching-subscriptions", type=non_negative_int, default=None,
                   help="wait for this many matching subscriptions first (default: 1 with --once/--times)")
    p.add_argument("--max-wait-time-secs", type=positive_float, default=None, help="give up waiting after this long")
    p.add_argument("--keep-alive", type=non_negative_float, default=0.1,
                   help="seconds to stay alive after the last message")
    p.add_argument("-p", "--print", type=non_negative_int, default=1, dest="print_nth",
                   help="print every N-th message (0: never)")
    _qos(p, depth_default=1)


def _simple_parsers(sub) -> None:
    node = sub.add_parser("node", help="list nodes, show one").add_subparsers(dest="verb", required=True)
    p = _verb(node, "list", "graph:cmd_node_list", "output a list of available nodes")
    p.add_argument("-a", "--all", action="store_true", help="also show hidden nodes")
    p.add_argument("-c", "--count-nodes", action="store_true", help="only show the number of nodes")
    _spin_time(p, LIST_SPIN_TIME_S)
    p = _verb(node, "info", "graph:cmd_node_info", "output information about a node")
    p.add_argument("node_name", help="node name to request information (e.g. /ball_tracker)")
    p.add_argument("--include-hidden", action="store_true", help="display hidden topics, services, and actions")
    _spin_time(p, LIST_SPIN_TIME_S)

    service = sub.add_parser("service", help="list and call services").add_subparsers(dest="verb", required=True)
    _list_options(_verb(service, "list", "graph:cmd_service_list", "output a list of available services"),
                  "service")
    p = _verb(service, "call", "service:cmd_call", "call a service")
    p.add_argument("service_name", help="name of the service to call (e.g. /sim/set_pause)")
    p.add_argument("service_type", help="type of the service (e.g. std_srvs/srv/SetBool)")
    p.add_argument("values", nargs="?", default="{}", help="the request's values in YAML (default: {})")
    p.add_argument("-r", "--rate", type=positive_float, default=None, help="repeat the call at this rate in Hz")
    p.add_argument("--timeout", type=positive_float, default=None,
                   help="give up after this many seconds waiting for the service or a response (default: wait)")

    param = sub.add_parser("param", help="node parameters").add_subparsers(dest="verb", required=True)
    p = _verb(param, "get", "param:cmd_get", "get a parameter")
    p.add_argument("node_name")
    p.add_argument("parameter_name")
    p.add_argument("--hide-type", action="store_true", help="print only the value")
    _spin_time(p, WAIT_FOR_NODE_S)
    p = _verb(param, "set", "param:cmd_set", "set a parameter")
    p.add_argument("node_name")
    p.add_argument("parameter_name")
    p.add_argument("value", help="value in YAML, e.g. 0.5, true, [1, 2]")
    _spin_time(p, WAIT_FOR_NODE_S)
    p = _verb(param, "dump", "param:cmd_dump", "print all parameters of a node as a parameter file")
    p.add_argument("node_name")
    _spin_time(p, WAIT_FOR_NODE_S)
    p = _verb(param, "list", "param:cmd_list", "list the parameter names of a node")
    p.add_argument("node_name")
    _spin_time(p, WAIT_FOR_NODE_S)
    p = _verb(param, "describe", "param:cmd_describe", "show the type, description and constraints of parameters")
    p.add_argument("node_name")
    p.add_argument("parameter_names", nargs="+")
    _spin_time(p, WAIT_FOR_NODE_S)
    p = _verb(param, "load", "param:cmd_load", "set parameters of a node from a parameter file")
    p.add_argument("node_name")
    p.add_argument("parameter_file")
    _spin_time(p, WAIT_FOR_NODE_S)

    bag = sub.add_parser("bag", help="record, play and summarize MCAP bags").add_subparsers(
        dest="verb", required=True)
    p = _verb(bag, "record", "bag:cmd_record", "record topics into an MCAP bag (rosbag2 layout)")
    p.add_argument("topics", nargs="*", help="topics to record")
    p.add_argument("-o", "--output", help="output bag folder (default: rosbag2_<date>)")
    p.add_argument("-a", "--all", action="store_true", help="record every topic")
    p.add_argument("--include-unpublished-topics", action="store_true",
                   help="also subscribe to selected topics that have no publisher yet")
    p.add_argument("--duration", type=positive_float, default=None,
                   help="ros2py extension: stop after this many seconds")
    p.add_argument("--max-cache-size", type=non_negative_int, default=MAX_CACHE_BYTES, metavar="BYTES",
                   help="messages taken but not yet written, at most (0: one message at a time); when the "
                        "writer falls behind, newer ones are dropped and counted (default: %(default)s)")
    _spin_time(p)
    p = _verb(bag, "info", "bag:cmd_info", "print a summary of an MCAP bag (folder or .mcap file)")
    p.add_argument("bag_path")
    p = _verb(bag, "play", "bag_play:cmd_play", "publish the messages of an MCAP bag (folder or .mcap file)")
    p.add_argument("bag_path")
    p.add_argument("-r", "--rate", type=positive_float, default=1.0, help="rate at which to play back (default: 1)")
    p.add_argument("-l", "--loop", action="store_true", help="play again from the start when done")
    p.add_argument("--topics", nargs="+", default=None, help="play only these topics")
    p.add_argument("--clock", type=positive_float, nargs="?", const=40.0, default=0.0, metavar="HZ",
                   help="publish /clock with the bag's time at HZ (default when given: 40)")
    p.add_argument("-d", "--delay", type=non_negative_float, default=0.0,
                   help="seconds to wait before playing (lets subscribers be discovered)")
    p.add_argument("--playback-duration", type=positive_float, default=None,
                   help="play only the first this many seconds of the bag (from --start-offset)")
    p.add_argument("--start-offset", type=non_negative_float, default=0.0, metavar="S",
                   help="start playing this many seconds into the bag (default: 0)")
    _spin_time(p)

    interface = sub.add_parser("interface", help="show interface definitions").add_subparsers(
        dest="verb", required=True)
    p = _verb(interface, "show", "interface:cmd_show", "print a message or service definition")
    p.add_argument("type_name", help="e.g. ball_tracker_msgs/msg/BallState")

    tf = sub.add_parser("tf", help="TF tools").add_subparsers(dest="verb", required=True)
    p = _verb(tf, "echo", "tf:cmd_echo", "print the transform from SOURCE into TARGET (like tf2_echo)")
    p.add_argument("target_frame")
    p.add_argument("source_frame")
    p.add_argument("--count", type=positive_int, default=None, help="print this many times and exit (default: forever)")
    p.add_argument("--rate", type=positive_float, default=1.0, help="printing rate in Hz (default: 1)")
    p.add_argument("--timeout", type=positive_float, default=5.0, help="wait this long for the transform (default: 5)")
    _spin_time(p)

    p = sub.add_parser("run", help="run an executable of a package", description="run an executable of a package")
    p.set_defaults(_target="run:cmd_run")
    p.add_argument("package_name")
    p.add_argument("executable_name")
    p.add_argument("argv", nargs=argparse.REMAINDER, help="arguments for the executable")


def _control_parsers(sub) -> None:
    control = sub.add_parser("control", help="talk to a controller manager").add_subparsers(dest="verb", required=True)

    def verb(name, target, help):
        p = _verb(control, name, f"control:{target}", help)
        p.add_argument("-c", "--controller-manager", default="/controller_manager",
                       help="name of the controller manager node (default: %(default)s)")
        _spin_time(p, WAIT_FOR_NODE_S)
        return p

    p = verb("list_controllers", "cmd_list_controllers", "output the loaded controllers, their type and state")
    p.add_argument("--verbose", "-v", action="store_true",
                   help="also print update rate, is_async and the interfaces of each controller")
    for flag in ("--claimed-interfaces", "--required-state-interfaces", "--required-command-interfaces",
                 "--chained-interfaces", "--exported-interfaces"):
        p.add_argument(flag, action="store_true")
    p.add_argument("--reference-interfaces", action="store_true", help="deprecated: --exported-interfaces")
    p = verb("list_hardware_components", "cmd_list_hardware_components", "output the hardware components")
    p.add_argument("--verbose", "-v", action="store_true", help="also list state interfaces and data types")
    p = verb("list_hardware_interfaces", "cmd_list_hardware_interfaces", "output the command and state interfaces")
    p.add_argument("--verbose", "-v", action="store_true", help="also print each interface's data type")
    p = verb("switch_controllers", "cmd_switch_controllers", "activate and deactivate controllers at once")
    p.add_argument("--activate", nargs="*", default=[], help="controllers to activate")
    p.add_argument("--deactivate", nargs="*", default=[], help="controllers to deactivate")
    strict = p.add_mutually_exclusive_group()
    strict.add_argument("--strict", action="store_true", help="fail the whole switch if one part fails")
    strict.add_argument("--best-effort", action="store_true", help="switch what can be switched")
    p.add_argument("--activate-asap", action="store_true", help="activate as soon as interfaces are ready")
    p.add_argument("--switch-timeout", type=positive_float, default=5.0, help="timeout in seconds (default: 5)")
    p = verb("load_controller", "cmd_load_controller", "load a controller")
    p.add_argument("controller_name")
    p.add_argument("--set-state", choices=["inactive", "active"], help="then configure (and activate) it")
    p = verb("set_controller_state", "cmd_set_controller_state", "configure, activate or deactivate a controller")
    p.add_argument("controller_name")
    p.add_argument("state", choices=["inactive", "active"])
    p = verb("unload_controller", "cmd_unload_controller", "unload a controller")
    p.add_argument("controller_name")
    verb("list_controller_types", "cmd_list_controller_types", "output the available controller types")
    p = verb("configure_controller", "cmd_configure_controller", "configure a loaded controller")
    p.add_argument("controller_name")
    p = verb("set_hardware_component_state", "cmd_set_hardware_component_state",
             "bring a hardware component to a lifecycle state")
    p.add_argument("hardware_component_name")
    p.add_argument("state", choices=["unconfigured", "inactive", "active"])


def _lifecycle_parsers(sub) -> None:
    lifecycle = sub.add_parser("lifecycle", help="managed (lifecycle) nodes").add_subparsers(dest="verb",
                                                                                           required=True)
    _spin_time(_verb(lifecycle, "nodes", "lifecycle:cmd_nodes", "output a list of nodes with lifecycle"),
               LIST_SPIN_TIME_S)
    p = _verb(lifecycle, "get", "lifecycle:cmd_get", "get lifecycle state for one or more nodes")
    p.add_argument("node_name", nargs="?", help="name of the ROS node (default: every lifecycle node)")
    _spin_time(p, WAIT_FOR_NODE_S)
    p = _verb(lifecycle, "list", "lifecycle:cmd_list", "output a list of available transitions")
    p.add_argument("node_name", help="name of the ROS node")
    p.add_argument("-a", "--all", action="store_true", help="display all existing transitions")
    _spin_time(p, WAIT_FOR_NODE_S)
    p = _verb(lifecycle, "set", "lifecycle:cmd_set", "trigger lifecycle state transition")
    p.add_argument("node_name", help="name of the ROS node")
    p.add_argument("transition", help="the label or the id of the transition (e.g. configure)")
    p.add_argument("--timeout", type=positive_float, default=120.0,
                   help="ros2py extension: wait this long for the answer, then ask get_state (default: %(default)s)")
    _spin_time(p, WAIT_FOR_NODE_S)


def _action_parsers(sub) -> None:
    action = sub.add_parser("action", help="list actions, send goals").add_subparsers(dest="verb", required=True)
    p = _verb(action, "list", "action:cmd_list", "output a list of action names")
    p.add_argument("-t", "--show-types", action="store_true", help="additionally show the action type")
    p.add_argument("-c", "--count-actions", action="store_true", help="only show the number of actions")
    _spin_time(p, LIST_SPIN_TIME_S)
    p = _verb(action, "info", "action:cmd_info", "print information about an action")
    p.add_argument("action_name", help="e.g. /scaled_joint_trajectory_controller/follow_joint_trajectory")
    p.add_argument("-t", "--show-types", action="store_true", help="additionally show the action type")
    p.add_argument("-c", "--count", action="store_true", help="only show the number of clients and servers")
    _spin_time(p, LIST_SPIN_TIME_S)
    p = _verb(action, "send_goal", "action:cmd_send_goal", "send an action goal")
    p.add_argument("action_name")
    p.add_argument("action_type", help="e.g. control_msgs/action/FollowJointTrajectory")
    p.add_argument("goal", help="goal values in YAML, e.g. \"{trajectory: {joint_names: [...], points: [...]}}\"")
    p.add_argument("-f", "--feedback", action="store_true", help="echo feedback messages for the goal")
    p.add_argument("--server-timeout", type=positive_float, default=10.0,
                   help="ros2py extension: seconds to wait for the server (default: %(default)s)")
    _spin_time(p, WAIT_FOR_NODE_S)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    _topic_parsers(sub)
    _simple_parsers(sub)
    _control_parsers(sub)
    _action_parsers(sub)
    _lifecycle_parsers(sub)
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    # Ctrl-C stops every verb even when we were started with SIGINT ignored (a background job
    # of a script, `cmd &`, inherits that): `bag record` would otherwise never finish its file
    # on `kill -INT`. ros2cli's verbs and rosbag2 install their own SIGINT handler too.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    from ball_balance.cli.session import teardowns_deferred

    with teardowns_deferred() as teardowns:
        code = _run_verb(args)
        _tear_down_within(TEARDOWN_DEADLINE_S, teardowns, code)
    return code


def _run_verb(args) -> int:
    """The verb's exit code; its failures as one line on stderr."""
    module_name, function_name = args._target.split(":")
    try:
        from ball_balance.cli.errors import CliError

        handler = getattr(importlib.import_module(f"ball_balance.cli.{module_name}"), function_name)
        code = handler(args)
    except KeyboardInterrupt:
        code = 0
    except CliError as error:
        print(f"{PROG}: {error}", file=sys.stderr)
        code = error.exit_code
    except BrokenPipeError:  # `ros2py topic echo ... | head`
        _discard_stdout()
        code = 0
    except Exception as error:  # noqa: BLE001 - one line, never a traceback wall
        if os.environ.get("ROS2PY_DEBUG"):
            raise
        text = str(error).strip().splitlines()
        print(f"{PROG}: {type(error).__name__}: {text[0] if text else ''} (ROS2PY_DEBUG=1 shows the traceback)",
              file=sys.stderr)
        code = 1
    return code or 0


def _discard_stdout() -> None:
    """Its reader has gone: what is still to be written goes nowhere (no error at exit)."""
    os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())


def _tear_down_within(deadline_s: float, teardowns: List[Callable[[], None]], code: int) -> None:
    """Run the sessions' rclpy teardowns once the output is out; after deadline_s, _exit(code).

    The deadline is kept outside the interpreter (_exit_after): rclpy's bindings hold the
    interpreter lock while rcl and the DDS participant tear down, so a hang there would stop
    any Python thread set to watch it. Dropping the sessions (gc) finalizes their contexts and
    participants within the deadline too, instead of at interpreter exit.
    """
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except BrokenPipeError:
            _discard_stdout()
    if not teardowns:
        return
    disarm = _exit_after(deadline_s, code)
    try:
        for teardown in teardowns:
            teardown()
        teardowns.clear()
        gc.collect()
    except BaseException:  # noqa: BLE001 - Ctrl-C or a failure in the teardown: the command is done
        os._exit(code)
    disarm()


def _exit_after(seconds: float, code: int) -> Callable[[], None]:
    """End the process with _exit(code) after `seconds`, unless the returned disarm() comes first.

    A POSIX timer (timer_create, SIGEV_THREAD) calls libc's _exit in a thread of its own with no
    Python code on the way, so it fires even while a call into C holds the interpreter lock.
    Without one, a daemon thread does it (which only a hang that releases the lock lets run).
    """
    import ctypes

    class SigEvent(ctypes.Structure):  # struct sigevent: sigval, signal, notify, thread function, attributes
        _fields_ = [("value", ctypes.c_long), ("signo", ctypes.c_int), ("notify", ctypes.c_int),
                    ("function", ctypes.c_void_p), ("attributes", ctypes.c_void_p), ("padding", ctypes.c_byte * 48)]

    class TimerSpec(ctypes.Structure):  # struct itimerspec: period, then first expiry (s, ns)
        _fields_ = [("period_s", ctypes.c_long), ("period_ns", ctypes.c_long),
                    ("expiry_s", ctypes.c_long), ("expiry_ns", ctypes.c_long)]

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.timer_create.argtypes = [ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p]
        libc.timer_settime.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p]
        libc.timer_delete.argtypes = [ctypes.c_void_p]
        event = SigEvent(value=code, notify=SIGEV_THREAD, function=ctypes.cast(libc._exit, ctypes.c_void_p))
        whole_s, fraction_s = divmod(seconds, 1.0)
        expiry = TimerSpec(expiry_s=int(whole_s), expiry_ns=int(fraction_s * 1e9))
        timer = ctypes.c_void_p()
        if libc.timer_create(CLOCK_MONOTONIC, ctypes.byref(event), ctypes.byref(timer)) != 0:
            raise OSError(ctypes.get_errno(), "timer_create failed")
        if libc.timer_settime(timer, 0, ctypes.byref(expiry), None) != 0:
            libc.timer_delete(timer)
            raise OSError(ctypes.get_errno(), "timer_settime failed")
        return lambda: libc.timer_delete(timer)
    except (AttributeError, OSError):
        import threading

        watchdog = threading.Timer(seconds, os._exit, (code,))
        watchdog.daemon = True
        watchdog.start()
        return watchdog.cancel


if __name__ == "__main__":
    sys.exit(main())
