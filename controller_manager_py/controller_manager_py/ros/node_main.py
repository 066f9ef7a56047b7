"""The few lines every executable's main() shares: init, spin, clean shutdown, clear errors.

A node that cannot start (a malformed parameter file, a bad parameter value, a missing
resource) prints one line naming the problem and exits non-zero, instead of a traceback.
Values given for parameters the node does not declare are reported once it is built
(controller_manager_py.parameters.report_unknown_parameters). A node's line saying what it
does (`announce()`, if it has one) comes after that check, so a node that is refused says
only why.

`--check-params` before `--ros-args` builds the node, checks what it was given (and runs the
node's `check()`, if it has one: the controller manager checks the controllers it would
start) and exits (0, or 2 with the one line) without spinning: a script checks a node's
parameters before it starts a graph (run it with ROS_AUTOMATIC_DISCOVERY_RANGE=OFF, and
nothing else sees it).
"""
from __future__ import annotations

import os
import sys
from typing import Any, Callable, List, Optional, Sequence, Tuple

from controller_manager_py.parameters import ParameterError, report_unknown_parameters

CHECK_PARAMS_FLAG = "--check-params"


class StartupError(RuntimeError):
    """Configuration that stops a node at start-up (the message is shown as is)."""


def run_node(make_node: Callable[[], Any], args: Optional[Sequence[str]] = None,
             multithreaded: bool = False) -> int:
    """Create the node, spin it until Ctrl-C or shutdown, and return the exit code."""
    import rclpy
    from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor

    from controller_manager_py.ros.params_files import ParamsFileError, check_params_files

    name = os.path.basename(sys.argv[0]) or getattr(make_node, "__name__", "node")
    args, check_only = _without_check_flag(list(sys.argv if args is None else args))
    unexpected = _not_ros_arguments(args[1:])
    if unexpected:
        print(f"{name}: cannot start: unexpected argument(s) {' '.join(unexpected)}: it takes ROS arguments "
              f"after --ros-args ({name} [{CHECK_PARAMS_FLAG}] --ros-args -p NAME:=VALUE ...)", file=sys.stderr)
        return 2
    try:  # before rcl, which would log its own error line for a malformed file
        check_params_files(args[1:])
    except ParamsFileError as error:
        print(f"{name}: cannot start: {error}", file=sys.stderr)
        return 2
    interrupts = _InterruptWhileSpinning()
    interrupts.install()  # before rclpy.init, whose own handler then runs first and calls ours
    try:
        _init_without_rcl_error_line(rclpy, args)
    except Exception as error:  # rcl reports a malformed argument here
        text = one_line(error)
        if type(error).__name__ == "UnknownROSArgsError":  # its message is only the list
            text = f"unknown ROS argument(s) {text} (ROS's are -p, -r, --params-file, --log-level, ...)"
        print(f"{name}: cannot start: {text}", file=sys.stderr)
        return 2
    node = None
    try:
        node = make_node()
        report_unknown_parameters(node)  # a typo in a parameter file: one line, not silence
        if check_only:
            if hasattr(node, "check"):
                node.check()
            return 0
        if hasattr(node, "announce"):
            node.announce()
        executor = MultiThreadedExecutor() if multithreaded else SingleThreadedExecutor()
        executor.add_node(node)
        interrupts.spinning = True
        executor.spin()
    except (ParameterError, StartupError) as error:
        print(f"{name}: cannot start: {error}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as error:
        if node is None and _raised_by_rclpy(error):
            # rclpy refusing what the node was given: a name that is not a ROS name, a value
            # of the wrong type for a parameter rclpy declares itself (use_sim_time)
            print(f"{name}: cannot start: {one_line(error)}", file=sys.stderr)
            return 2
        # A SIGINT/SIGTERM shuts the context down under the executor, which may then raise
        # "context is not valid" instead of ExternalShutdownException: that is a clean exit.
        if rclpy.ok():
            raise
    finally:
        # A second Ctrl-C (or the TERM a launcher sends after the terminal's INT) must not
        # interrupt the shutdown half-way with a traceback: the first one already stops it.
        ignore_stop_signals()
        if node is not None:
            try:
                node.destroy_node()
            except Exception:  # noqa: BLE001 - best effort at shutdown
                pass
        if rclpy.ok():
            rclpy.try_shutdown()
    return 0


class _InterruptWhileSpinning:
    """Ctrl-C before the node spins raises KeyboardInterrupt, as usual. Once it spins, rclpy's
    own handler has already shut the context down, which ends the spin; a KeyboardInterrupt
    on top would be raised wherever the main thread happens to be. Inside a garbage-collected
    Future's __del__ (CI, once in ~20 runs) Python prints it as a traceback and drops it."""

    def __init__(self):
        self.spinning = False

    def install(self) -> None:
        import signal

        try:
            signal.signal(signal.SIGINT, self._on_interrupt)
        except ValueError:  # not the main thread (run_node called from a test helper)
            pass

    def _on_interrupt(self, signum, frame) -> None:
        if not self.spinning:
            raise KeyboardInterrupt


def ignore_stop_signals() -> None:
    """From here on Ctrl-C and SIGTERM do nothing: a shutdown already under way finishes."""
    import signal

    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            signal.signal(sig, signal.SIG_IGN)
        except ValueError:  # not the main thread (run_node called from a test helper)
            pass


def main_for(make_node, multithreaded: bool = False) -> Callable[[], None]:
    """Build a console-script main(): `main = main_for(MyNode)`."""

    def main(args=None):
        sys.exit(run_node(make_node, args, multithreaded))

    return main


def _without_check_flag(argv: List[str]) -> Tuple[List[str], bool]:
    """argv without --check-params (looked for before --ros-args only), and whether it was there."""
    end = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    if CHECK_PARAMS_FLAG not in argv[:end]:
        return argv, False
    at = argv.index(CHECK_PARAMS_FLAG)
    return argv[:at] + argv[at + 1:], True


def _not_ros_arguments(args: List[str]) -> List[str]:
    """What a node that takes only ROS arguments would ignore: anything before --ros-args, or
    after the `--` that ends a --ros-args section (a typo such as `--check-param`, or `-p` given
    without --ros-args)."""
    unexpected, in_ros_args = [], False
    for arg in args:
        if arg == "--ros-args":
            in_ros_args = True
        elif in_ros_args and arg == "--":
            in_ros_args = False
        elif not in_ros_args:
            unexpected.append(arg)
    return unexpected


def _init_without_rcl_error_line(rclpy, args: List[str]) -> None:
    """rclpy.init, with what rcl logs meanwhile held back: rcl logs "Failed to parse global
    arguments" for an argument it cannot parse and then raises with the reason, which is
    the one line shown. Anything else it logged is passed on once init succeeded."""
    import tempfile

    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 2)
        try:
            rclpy.init(args=args)
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        held.seek(0)
        logged = held.read()
    if logged:
        sys.stderr.write(logged.decode(errors="replace"))


def _raised_by_rclpy(error: BaseException) -> bool:
    from rclpy.exceptions import InvalidParameterTypeException, NameValidationException

    if isinstance(error, (NameValidationException, InvalidParameterTypeException)):
        return True
    frames = error.__traceback__
    while frames is not None and frames.tb_next is not None:
        frames = frames.tb_next
    return isinstance(error, ValueError) and frames is not None and \
        f"{os.sep}rclpy{os.sep}" in frames.tb_frame.f_code.co_filename


def one_line(error: BaseException) -> str:
    """An rclpy or rcl error as one line: its reason (and the name it is about), without the C
    source location rcl appends."""
    lines = [line.strip() for line in str(error).strip().splitlines()] or [type(error).__name__]
    text = lines[0]
    if text.endswith(":") and len(lines) > 1:  # rclpy's name errors: the reason, then the name
        text = f"{text[:-1]}: {lines[1]}"
    # rcl appends the C source location (", at /project/src/...") to its messages
    return text.split(", at /")[0]
