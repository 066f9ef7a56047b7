"""The `controller_manager` node: hardware from the robot description, the loop thread,
ros2_control's services, ~/activity, statistics, introspection and /diagnostics.

Threads: the read-update-write loop runs in its own thread (manager/loop.py); services,
subscriptions and the diagnostics timer run in the executor, so a slow service never
delays a cycle (the GIL switch interval is lowered so the loop gets the interpreter back
quickly after its sleep, and the executor thread shares the loop thread's CPU at a lower
priority, so it never runs, and never asks for the interpreter, while a cycle runs).
~/statistics and ~/introspection_data are filled and published in the loop's idle time
after a cycle (when the cycle ran late, only once a publication is a whole publishing
period overdue), because building a `full` message holds the interpreter for ~0.2 ms,
which from another thread would delay the loop's wake-up.

Robot description, first found: parameter `robot_description` (URDF text), parameter
`robot_description_file` (a path), else the `robot_description_topic` topic (default
/robot_description, transient local) — the hardware is loaded from the first message.
Controllers: every `<name>.type` in the manager's parameters (ros2_control YAML layout)
is loadable by name; those in `activate_controllers` are loaded, configured and activated
at start, those in `inactive_controllers` loaded and configured. Per-controller
parameters come from the same --params-file (the `<name>:` section) or from a file in
`<name>.params_file`. `<name>.fallback_controllers` lists fallbacks.

Time: the cycle's time is the manager's clock (a simulated hardware's, else the system's);
the node's ROS clock stamps messages. The node's own timers (start-up, /diagnostics) run
on the steady clock: with use_sim_time:=true and the simulated arm in
this very process, /clock only ticks once the loop is started, so start-up on the ROS clock
would wait for itself.
"""
from __future__ import annotations

import os
import signal
import sys
import threading
import time
import warnings

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.logging import LoggingSeverity
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import String

from ..hardware_interface.types import State
from ..manager.controller_manager import ControllerError, ControllerManager
from ..manager.diagnostics import THRESHOLD_PARAMS, roll_up
from ..manager.introspection import introspection_entries, statistics_entries
from ..manager.loop import WAKE_TAIL_MAX_FRACTION, ControlLoop
from ..manager.resource_manager import ResourceError
from ..manager.switching import STRICT, SwitchError
from ..parameters import UNKNOWN_PARAMETERS, Param, ParameterError, closest_name, declare_parameters
from ..realtime import lock_memory, set_cpu_affinity, set_process_realtime_priority
from ..text_files import TextFileError, read_text_file
from .node_main import StartupError, one_line
from .params_files import ParamsFileError, check_params_file
from .services import ControllerManagerServices
from .statistics_publisher import StatisticsRegistry

_NONE = [""]  # an empty string array parameter (rclpy cannot type an empty list)

SCHEMA = (
    Param("update_rate", 100, "rate of the read-update-write loop", unit="Hz", min=1, max=10000, read_only=True,
          user_facing=True),
    Param("robot_description", "", "URDF text with <ros2_control> tags (empty: file or topic)", user_facing=True),
    Param("robot_description_file", "", "path of a URDF file (used when robot_description is empty)", user_facing=True),
    Param("robot_description_topic", "/robot_description", "topic (transient local) when no parameter is set",
          user_facing=True),
    Param("hardware_components_initial_state.unconfigured", _NONE, "components only loaded at start", user_facing=True),
    Param("hardware_components_initial_state.inactive", _NONE, "components configured but not activated",
          user_facing=True),
    Param("hardware_synchronization.expect_blocking_read_write", False,
          "hardware read() blocks and sets the pace: the loop does not sleep"),
    Param("hardware_synchronization.minimum_cycle_time", 0.0, "with blocking read/write: least time per cycle",
          unit="s", min=0.0),
    Param("enforce_command_limits", True, "clamp commands to the URDF joint limits before write()"),
    Param("allow_joints_without_limits", False, "accept revolute/prismatic joints that have no URDF <limit> "
          "(their commands are then not limited)"),
    Param("activate_controllers", _NONE, "controllers loaded, configured and activated at start (in order)",
          user_facing=True),
    Param("inactive_controllers", _NONE, "controllers loaded and configured at start", user_facing=True),
    Param("statistics.publish_rate", 20.0, "rate of ~/statistics and ~/introspection_data", unit="Hz",
          min=0.1, max=1000.0, user_facing=True),
    Param("diagnostics.period", 1.0, "period of /diagnostics (statistics windows restart after each)", unit="s",
          min=0.05, user_facing=True),
    Param("thread_priority", 50, "SCHED_FIFO priority of the loop thread (0 = normal scheduling)", min=0, max=99,
          user_facing=True),
    Param("cpu_affinity", [-1], "CPUs the loop thread may run on ([-1]: any); with loop.executor_on_loop_cpu only "
          "the first (with [-1]: the last CPU the process may use)", user_facing=True),
    Param("loop.executor_on_loop_cpu", True, "the executor thread and the loop thread share one CPU (the first of "
          "cpu_affinity; with [-1] the last CPU the process may use): at its lower priority the executor cannot "
          "run, so cannot take Python's interpreter lock, while a cycle runs"),
    Param("loop.executor_thread_priority", 40, "SCHED_FIFO priority of the executor thread and of the threads "
          "started before it, the middleware's receive threads among them (0 = normal): a preempted thread "
          "holding Python's interpreter lock would stall the loop, and a starved receive thread delays "
          "commands", min=0, max=99),
    Param("loop.gil_switch_interval", 1e-4, "Python's thread switch interval: how long a thread waiting for the "
          "interpreter sleeps before it asks the holder to give it up, and again between such requests (shorter: "
          "the loop's polling can starve a holder on its own CPU, see manager/loop.py)", unit="s",
          min=1e-6, max=0.01),
    Param("loop.hold_interpreter", True, "the loop keeps Python's interpreter lock from its wake-up until it "
          "sleeps (the switch interval is raised meanwhile), so no other thread interrupts a cycle"),
    Param("loop.wake_tail", 3e-4, "before the spin tail, this part of the wait is slept holding the interpreter: "
          "the loop takes the lock back this long before the deadline, so waiting for a thread that holds it "
          f"does not delay the cycle (0: off; at most {WAKE_TAIL_MAX_FRACTION:.0%} of the period)", unit="s",
          min=0.0, max=0.01),
    Param("loop.spin_tail", 1e-4, "the last part before a deadline is a busy wait holding the interpreter (beats the "
          "kernel's wake-up "
          "latency; costs that much CPU per cycle)", unit="s", min=0.0, max=0.01),
    Param("loop.gc_mode", "idle", "Python garbage collection: idle (objects at start frozen, collections run in "
          "the loop's slack), freeze (frozen at start, automatic), automatic (Python's default)",
          choices=("idle", "freeze", "automatic")),
    Param("lock_memory", False, "mlockall the process at start so no page fault delays a cycle "
          "(needs RLIMIT_MEMLOCK)"),
    Param("loop.cycle_log_file", "", "write the last 65536 cycles' deadline, start and end times (monotonic s) "
          "to this .npz file at exit (timing analysis; empty: off)"),
    *THRESHOLD_PARAMS,
)
CONTROLLER_KEYS = ("type", "fallback_controllers", "params_file")


class ControllerManagerNode(Node):
    def __init__(self, node_name: str = "controller_manager", **node_kwargs):
        """node_kwargs: rclpy Node's (e.g. `context`)."""
        super().__init__(node_name, allow_undeclared_parameters=True, **node_kwargs)
        self.params = declare_parameters(self, SCHEMA)
        sys.setswitchinterval(self.params["loop.gil_switch_interval"])
        if self.params["lock_memory"]:
            problem = lock_memory()
            if problem is not None:
                self.get_logger().warning(f"lock_memory: cannot lock the process memory ({problem}); "
                                          "a page fault may delay a cycle")
        config = self._controller_config()
        self.cm = ControllerManager(self.params["update_rate"], self.get_logger(), self._make_controller_node, config)
        self.cm.release_node = self._release_controller_node
        self.cm.alive = self.context.ok
        self.loop = None
        self._unattached = []
        self._checking = False  # check(): controllers are configured only to be checked
        self.cm_services = ControllerManagerServices(self, self.cm, self.controller_type)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        from controller_manager_msgs.msg import ControllerManagerActivity
        self.activity_pub = self.create_publisher(ControllerManagerActivity, "~/activity", latched)
        self.statistics = StatisticsRegistry(self, "~/statistics")
        self.introspection = StatisticsRegistry(self, "~/introspection_data")
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._published_version = -1
        self._refusal_counts = {}  # refusal counters at the previous /diagnostics (WARN when they grow)
        self._cycles_since_due = 0
        self._publish_every = max(1, round(self.cm.update_rate / self.params["statistics.publish_rate"]))
        # registries still to publish this round, and each one's last publishing time (s)
        self._pending_publish = []
        self._publish_cost = {}
        # woken by each change instead of polling: an executor wake-up is a moment the loop
        # may find the interpreter lock taken
        self._registry_change = self.create_guard_condition(self.on_registry_change)
        self.cm.on_change = self._registry_change.trigger
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(self.params["diagnostics.period"], self.on_diagnostics_timer, clock=steady)
        self._description_sub = None
        urdf = self._description_from_parameters()
        if urdf:
            self._load_hardware(urdf, at_startup=True)
        else:
            topic = self.params["robot_description_topic"]
            self._description_sub = self.create_subscription(String, topic, self.on_robot_description, latched)
        self._start_timer = self.create_timer(0.01, self.on_start, clock=steady)
        self.add_on_set_parameters_callback(self._refuse_unknown_names)

    def _refuse_unknown_names(self, parameters) -> SetParametersResult:
        """The manager takes any `<controller>.type|params_file|fallback_controllers` (a spawner
        sets them), so it allows undeclared parameters; any other name it does not declare is
        refused (`param set /controller_manager update_rat 100` would succeed and do nothing)."""
        for parameter in parameters:
            owner, _, leaf = parameter.name.rpartition(".")
            if self.has_parameter(parameter.name) or parameter.name == UNKNOWN_PARAMETERS.name or \
                    (owner and leaf in CONTROLLER_KEYS):
                continue
            close = closest_name(parameter.name, self._parameters)
            return SetParametersResult(successful=False, reason=(
                f"'{parameter.name}' is not a parameter of {self.get_fully_qualified_name()}"
                + (f" (did you mean {close}?)" if close else "")
                + "; a controller's own parameters are set on its node"))
        return SetParametersResult(successful=True)

    def announce(self) -> None:
        """The start-up line, once the parameters are checked (ros/node_main.py run_node)."""
        if self._description_sub is not None:
            self.get_logger().info(f"waiting for the robot description on {self.params['robot_description_topic']}")
        else:
            self._log_hardware_loaded()

    # ---- configuration -------------------------------------------------------------------
    def _controller_config(self):
        overrides = getattr(self, "_parameter_overrides", {})
        config = {}
        for key, param in overrides.items():
            name, _, leaf = key.rpartition(".")
            if leaf in CONTROLLER_KEYS and name and not name.startswith(("diagnostics", "hardware_")):
                config.setdefault(name, {})[leaf] = param.value
                if not self.has_parameter(key):
                    self.declare_parameter(key, param.value)
        return config

    def _description_from_parameters(self) -> str:
        urdf, path = self.params["robot_description"], self.params["robot_description_file"]
        if urdf:
            return urdf
        if path:
            try:
                return read_text_file(path, "robot description")
            except TextFileError as error:
                raise ParameterError(f"parameter 'robot_description_file': {error}") from None
        return ""

    def _initial_states(self):
        states = {}
        for label, state in (("unconfigured", State.UNCONFIGURED), ("inactive", State.INACTIVE)):
            for name in self.params[f"hardware_components_initial_state.{label}"]:
                if name:
                    states[name] = state
        return states

    def _load_hardware(self, urdf: str, at_startup: bool) -> bool:
        try:
            self.cm.load_robot_description(urdf, node=self, initial_states=self._initial_states(),
                                           enforce_command_limits=self.params["enforce_command_limits"],
                                           require_limits=not self.params["allow_joints_without_limits"])
        except (ResourceError, ControllerError) as error:
            if at_startup:  # run_node prints it as one line and exits non-zero
                raise ParameterError(f"robot description: {error}") from None
            self.get_logger().error(f"robot description: {error}; waiting for another one")
            return False
        if not at_startup:
            self._log_hardware_loaded()
        return True

    def _log_hardware_loaded(self) -> None:
        names = ", ".join(f"{c.name} ({c.info.plugin})" for c in self.cm.rm.components.values())
        self.get_logger().info(f"hardware loaded: {names}")

    def on_robot_description(self, msg: String) -> None:
        if self.cm.rm.components:
            return
        if self._load_hardware(msg.data, at_startup=False):
            self.destroy_subscription(self._description_sub)
            self._description_sub = None
            self.on_start()

    # ---- controller nodes ------------------------------------------------------------------
    def _make_controller_node(self, name: str):
        """The controller's own node. Like ros2_control, it does not take the manager's global
        command line as is (a `-r __node:=...` or `-p` meant for the manager would hit every
        controller): it gets the manager's --params-file files and remaps (node renames left
        out), the manager's use_sim_time, and `<name>.params_file` when set."""
        params_file = self.cm.controller_config.get(name, {}).get("params_file")
        if self.has_parameter(f"{name}.params_file"):
            params_file = self.get_parameter(f"{name}.params_file").value
        use_sim_time = bool(self.get_parameter("use_sim_time").value)
        cli_args = ["--ros-args", *forwarded_ros_args(sys.argv), "-p", f"use_sim_time:={str(use_sim_time).lower()}"]
        if params_file:
            try:  # rcl's own error for it would name neither the file nor the controller
                check_params_file(str(params_file))
            except ParamsFileError as error:
                raise ControllerError(f"controller '{name}': {error}") from None
            cli_args += ["--params-file", str(params_file)]
        try:
            node = rclpy.create_node(name, namespace=self.get_namespace(), context=self.context, cli_args=cli_args,
                                     use_global_arguments=False)
        except Exception as error:  # noqa: BLE001 - rcl refuses the file's content (a mixed-type list, ...)
            raise ControllerError(f"controller '{name}': {one_line(error)}") from None
        if self._checking:
            node.get_logger().set_level(LoggingSeverity.WARN)
        if self.executor is not None:
            self.executor.add_node(node)
        else:
            self._unattached.append(node)
        return node

    def _release_controller_node(self, node) -> None:
        if self.executor is not None:
            self.executor.remove_node(node)
        with warnings.catch_warnings():
            if not self.context.ok():  # at exit: rcl cannot finish the rosout publisher, as expected
                warnings.simplefilter("ignore", RuntimeWarning)
            node.destroy_node()

    def controller_type(self, name: str) -> str:
        """`<name>.type` (and `<name>.fallback_controllers`) as currently set, e.g. by a spawner."""
        config = self.cm.controller_config.setdefault(name, {})
        for leaf in ("type", "fallback_controllers"):
            if self.has_parameter(f"{name}.{leaf}"):
                config[leaf] = self.get_parameter(f"{name}.{leaf}").value
        return config.get("type", "")

    # ---- start-up: spawn listed controllers, start the loop ---------------------------------
    def on_start(self) -> None:
        if self._start_timer is not None:
            self._start_timer.cancel()
        for node in self._unattached:
            self.executor.add_node(node)
        self._unattached = []
        if not self.cm.rm.components or self.loop is not None or not self.context.ok():
            return  # (a Ctrl-C during start-up: nothing to start)
        activate, inactive = self._controllers_at_start()
        for name in [*activate, *inactive]:
            try:
                self.spawn(name)
            except (ControllerError, SwitchError) as error:
                self.get_logger().error(f"cannot spawn '{name}': {error}")
        try:
            started = [n for n in activate if n in self.cm.controllers]
            self.cm.switch_controller(started, [], STRICT)
        except SwitchError as error:
            self.get_logger().error(f"cannot activate {activate}: {error}")
        if self.params["loop.executor_thread_priority"] > 0:
            # this callback runs in the executor thread; the middleware's threads, started with
            # the node, receive what the executor runs (command topics, services) and answer
            # discovery: normally scheduled beside a SCHED_FIFO camera chain that fills both
            # cores of a slow machine, they leave the joint commands seconds late and a new
            # subscriber (a bag recorder) unmatched for its whole recording. The loop thread,
            # started below, sets its own priority.
            set_process_realtime_priority(self.params["loop.executor_thread_priority"])
        loop_cpus = [cpu for cpu in self.params["cpu_affinity"] if cpu >= 0]
        if self.params["loop.executor_on_loop_cpu"]:
            loop_cpus = [shared_loop_cpu(loop_cpus)]
            if not set_cpu_affinity(loop_cpus):
                self.get_logger().warning("loop.executor_on_loop_cpu: cannot pin the executor thread to CPU "
                                          f"{loop_cpus[0]}")
        blocking = self.params["hardware_synchronization.expect_blocking_read_write"]
        self.loop = ControlLoop(self.cm, blocking, self.params["hardware_synchronization.minimum_cycle_time"],
                                self.params["thread_priority"],
                                loop_cpus,
                                wake_tail=self.params["loop.wake_tail"], spin_tail=self.params["loop.spin_tail"],
                                gc_mode=self.params["loop.gc_mode"],
                                hold_interpreter=self.params["loop.hold_interpreter"],
                                cycle_log=self.params["loop.cycle_log_file"])
        self.loop.idle_hook = self.on_loop_idle
        if self.loop.wake_tail < self.params["loop.wake_tail"]:
            self.get_logger().info(f"loop.wake_tail: {self.params['loop.wake_tail'] * 1e6:.0f} us is more than "
                                   f"{WAKE_TAIL_MAX_FRACTION:.0%} of the {self.loop.period * 1e3:g} ms period; "
                                   f"{self.loop.wake_tail * 1e6:.0f} us used")
        self.on_registry_change()
        if not self.context.ok():
            return
        self.loop.start()
        self.get_logger().info(f"update loop running at {self.cm.update_rate} Hz; active controllers: "
                               f"{[s.name for s in self.cm.ordered]}")

    def _controllers_at_start(self) -> tuple:
        """(activate_controllers, inactive_controllers) without the empty placeholder."""
        return ([n for n in self.params["activate_controllers"] if n],
                [n for n in self.params["inactive_controllers"] if n])

    def spawn(self, name: str) -> None:
        self.cm.load_controller(name, self.controller_type(name))
        self.cm.configure_controller(name)

    def check(self) -> None:
        """`--check-params`: every controller the start would spawn is loaded and configured as
        it would be (its parameters, its own checks, the interfaces it claims), then unloaded.
        Without the hardware (a description still to come on the topic) only its parameters
        are checked. Raises StartupError with the first controller's reason. What a controller
        logs below a warning (its start-up line) is not shown: nothing runs."""
        self._checking = True
        for name in [n for names in self._controllers_at_start() for n in names]:
            try:
                if self.cm.rm.components:
                    self.spawn(name)
                else:
                    spec = self.cm.load_controller(name, self.controller_type(name))
                    spec.c.load_params(spec.param_values)
            except (ControllerError, ParameterError) as error:
                raise StartupError(str(error) if str(error).startswith("controller '")
                                   else f"controller '{name}': {error}") from None
            finally:
                if name in self.cm.controllers:
                    self.cm.unload_controller(name)

    # ---- publishers -------------------------------------------------------------------------
    def on_registry_change(self) -> None:
        """Executor, after the manager's `on_change` (any thread): the statistics names and an
        ~/activity message as of now (several changes in a row: once, with the latest)."""
        version = self.cm.version
        if version != self._published_version:
            self._published_version = version
            self.statistics.set_entries(statistics_entries(self.cm, self.get_name()))
            self.introspection.set_entries(introspection_entries(self.cm))
            self.activity_pub.publish(self.cm_services.activity())

    def on_loop_idle(self, budget: float) -> None:
        """Loop thread, after each cycle (`budget` s before the loop must wait for its next
        deadline, 0 when the cycle left no slack): ~/statistics then ~/introspection_data at
        statistics.publish_rate, each when its last measured publishing time (x1.5) fits the
        budget, else in a later cycle, so publishing does not make a cycle start late; but a
        publication a whole publishing period overdue goes out anyway, so a loop that keeps
        overrunning (a machine too slow for its rate) still reports, and the robot manager's
        watchdog, which takes silence for a stalled manager, sees it cycling."""
        self._cycles_since_due += 1
        if self._cycles_since_due >= self._publish_every and not self._pending_publish:
            self._cycles_since_due = 0
            self._pending_publish = [self.statistics, self.introspection]
        if not self._pending_publish:
            return
        registry = self._pending_publish[0]
        cost = self._publish_cost.get(id(registry), 0.0)
        overdue = self._cycles_since_due >= self._publish_every
        if 1.5 * cost > budget and not overdue:
            self._publish_cost[id(registry)] = 0.95 * cost  # a cost measured in a bad moment fades
            return
        start = time.monotonic()
        registry.publish()
        self._publish_cost[id(registry)] = time.monotonic() - start
        self._pending_publish.pop(0)

    def on_diagnostics_timer(self) -> None:
        thresholds = {p.name: self.params[p.name] for p in THRESHOLD_PARAMS}
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        for status in roll_up(self.cm, thresholds, self._refusal_counts):
            msg.status.append(DiagnosticStatus(
                level=bytes([status.level]), name=f"{self.get_name()}: {status.name}", message=status.message,
                hardware_id=self.get_fully_qualified_name(),
                values=[KeyValue(key=k, value=v) for k, v in status.values]))
        self.diagnostics_pub.publish(msg)
        self.cm.request_stats_reset()

    def destroy_node(self):
        """Stop the loop, then deactivate and unload the controllers and shut the hardware down.
        Usually runs after Ctrl-C has shut the ROS context down: the loop has stopped by itself
        at its first failed publish (cm.alive), and rcl's complaints about finishing the rosout
        publishers of a shut-down context are expected, not shown. A second Ctrl-C meanwhile
        says that the shutdown is under way; a third exits at once."""
        if not self.context.ok():  # stopping after Ctrl-C (not an in-process user destroying the node)
            _tolerate_further_interrupts(self.get_name())
        if self.loop is not None:
            self.loop.stop()
        with warnings.catch_warnings():
            if not self.context.ok():
                warnings.simplefilter("ignore", RuntimeWarning)
            try:
                self.cm.shutdown()
            except Exception as error:  # noqa: BLE001 - best effort at exit
                if self.context.ok():
                    self.get_logger().error(f"shutdown: {error!r}")
            self.cm.on_change = lambda: None   # the guard condition goes with the node
            return super().destroy_node()


def shared_loop_cpu(cpu_affinity) -> int:
    """The one CPU of the loop and executor threads (executor_on_loop_cpu): the first of the
    loop's `cpu_affinity`, or (none given) the last CPU this process may run on."""
    if cpu_affinity:
        return int(cpu_affinity[0])
    return max(os.sched_getaffinity(0))


def _tolerate_further_interrupts(name: str) -> None:
    """While shutting down (main thread only): a Ctrl-C prints one line instead of raising
    KeyboardInterrupt in the middle of the hardware's shutdown; a second one exits at once."""
    if threading.current_thread() is not threading.main_thread():
        return
    interrupts = [0]

    def on_interrupt(signum, frame):
        interrupts[0] += 1
        if interrupts[0] == 1:
            print(f"{name}: already stopping (controllers and hardware are being shut down); "
                  "Ctrl-C again to exit at once", file=sys.stderr, flush=True)
        else:
            os._exit(130)
    try:
        signal.signal(signal.SIGINT, on_interrupt)
    except (ValueError, OSError):
        pass


def forwarded_ros_args(argv) -> list:
    """From the manager's command line: the --params-file files, remaps (except node renames)
    and the log level, for a controller's node."""
    out, inside, i = [], False, 0
    while i < len(argv):
        token = argv[i]
        if token == "--ros-args":
            inside = True
        elif token == "--":
            inside = False
        elif inside and token in ("--params-file", "-r", "--remap", "--log-level") and i + 1 < len(argv):
            value = argv[i + 1]
            rename = token in ("-r", "--remap") and ("__node:=" in value or "__name:=" in value)
            if not rename:
                out += [token, value]
            i += 1
        i += 1
    return out
