"""`spawner`: load, configure and activate controllers of a running controller manager.

Same command line as ros2_control's spawner (the common options):
    spawner joint_state_broadcaster forward_position_controller [-c /controller_manager]
            [--inactive | --activate] [--load-only] [-t TYPE] [-p PARAM_FILE]
            [--activate-as-group] [--controller-manager-timeout S] [--switch-timeout S]
            [-u | --unload-on-kill]
Exits 0 when every controller reached the requested state, 1 otherwise (one line why).
With --unload-on-kill it then waits; Ctrl-C/SIGTERM, then or while spawning, deactivates and unloads
them and exits 0.

A signal only sets a flag, checked between service calls and while one is awaited: raising from the
handler could land inside rclpy's C code, which turns the interrupt into a SystemError. Without
--unload-on-kill an awaited call is abandoned at once; with it the call finishes (within its timeout)
so that the unload sees the manager's true state.
"""
from __future__ import annotations

import argparse
import signal
import sys
import time

import rclpy
import rclpy.signals
from controller_manager_msgs.srv import (
    ConfigureController,
    ListControllers,
    LoadController,
    SwitchController,
    UnloadController,
)
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters

from controller_manager_py.ros.params_files import ParamsFileError, check_params_file


class SpawnError(RuntimeError):
    pass


class Interrupted(Exception):
    """Ctrl-C or SIGTERM, seen at a point where stopping is safe."""


def parse_args(argv):
    parser = argparse.ArgumentParser(prog="spawner", description=__doc__.splitlines()[0])
    parser.add_argument("controller_names", nargs="+")
    parser.add_argument("-c", "--controller-manager", default="/controller_manager")
    parser.add_argument("-p", "--param-file", help="controller parameters file (sets <name>.params_file)")
    parser.add_argument("-t", "--controller-type", help="controller type (sets <name>.type)")
    parser.add_argument("--load-only", action="store_true", help="only load the controllers")
    state = parser.add_mutually_exclusive_group()
    state.add_argument("--inactive", action="store_true", help="configure but leave inactive")
    state.add_argument("--activate", action="store_true", help="configure and activate (the default)")
    parser.add_argument("--activate-as-group", action="store_true", help="activate all in one switch")
    parser.add_argument("-u", "--unload-on-kill", action="store_true",
                        help="wait until killed, then deactivate and unload the controllers")
    parser.add_argument("--controller-manager-timeout", type=float, default=10.0)
    parser.add_argument("--switch-timeout", type=float, default=5.0)
    parser.add_argument("--service-call-timeout", type=float, default=10.0)
    return parser.parse_args(argv)


class Spawner:
    def __init__(self, node, args):
        self.node, self.args = node, args
        self.cm = args.controller_manager.rstrip("/") or "/controller_manager"
        self.stop_requested = False
        self.spawning = True

    def request_stop(self, signum=None, frame=None) -> None:
        self.stop_requested = True

    def _stop_now(self, in_call: bool) -> bool:
        """Whether a stop request interrupts here: never during the unload, and inside a call only
        when no unload follows."""
        return self.stop_requested and self.spawning and not (in_call and self.args.unload_on_kill)

    def call(self, srv_type, name: str, request, timeout: float):
        if self._stop_now(in_call=False):
            raise Interrupted
        client = self.node.create_client(srv_type, f"{self.cm}/{name}")
        try:
            deadline = time.monotonic() + timeout
            while not client.wait_for_service(timeout_sec=0.1):
                if self._stop_now(in_call=True):
                    raise Interrupted
                if time.monotonic() > deadline:
                    raise SpawnError(f"controller manager {self.cm} not available ({self.cm}/{name} missing "
                                     f"after {timeout:g} s)")
            future = client.call_async(request)
            deadline = time.monotonic() + self.args.service_call_timeout
            while not future.done():
                if self._stop_now(in_call=True):
                    raise Interrupted
                if time.monotonic() > deadline:
                    raise SpawnError(f"{self.cm}/{name} did not answer within {self.args.service_call_timeout:g} s")
                rclpy.spin_once(self.node, timeout_sec=0.1)
            return future.result()
        finally:
            self.node.destroy_client(client)

    def set_param(self, name: str, value: str) -> None:
        request = SetParameters.Request(parameters=[Parameter(
            name=name, value=ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value))])
        result = self.call(SetParameters, "set_parameters", request, self.args.controller_manager_timeout)
        if not result.results or not result.results[0].successful:
            raise SpawnError(f"cannot set {self.cm} parameter '{name}'")

    def loaded(self):
        response = self.call(ListControllers, "list_controllers", ListControllers.Request(),
                             self.args.controller_manager_timeout)
        return {c.name: c.state for c in response.controller}

    def switch(self, names):
        request = SwitchController.Request(activate_controllers=list(names), strictness=SwitchController.Request.STRICT,
                                           activate_asap=True)
        request.timeout.sec = int(self.args.switch_timeout)
        request.timeout.nanosec = int((self.args.switch_timeout % 1) * 1e9)
        response = self.call(SwitchController, "switch_controller", request, self.args.switch_timeout + 5.0)
        if not response.ok:
            why = getattr(response, "message", "") or "see the controller manager's log"
            raise SpawnError(f"failed to activate {', '.join(names)}: {why}")

    def run(self) -> None:
        a = self.args
        to_activate = []
        for name in a.controller_names:
            if a.controller_type:
                self.set_param(f"{name}.type", a.controller_type)
            if a.param_file:
                self.set_param(f"{name}.params_file", a.param_file)
            state = self.loaded().get(name)
            if state is not None:
                print(f"[spawner] controller '{name}' already loaded ({state})", file=sys.stderr)
            elif not self.call(LoadController, "load_controller", LoadController.Request(name=name),
                               a.controller_manager_timeout).ok:
                raise SpawnError(f"failed loading controller '{name}' (unknown type or bad parameters: see the "
                                 "controller manager's log)")
            if a.load_only:
                print(f"[spawner] loaded {name}")
                continue
            if self.loaded().get(name) == "unconfigured" and not self.call(
                    ConfigureController, "configure_controller", ConfigureController.Request(name=name),
                    a.controller_manager_timeout).ok:
                raise SpawnError(f"failed to configure controller '{name}' (see the controller manager's log)")
            if a.inactive:
                print(f"[spawner] configured {name} (inactive)")
            elif a.activate_as_group:
                to_activate.append(name)
            elif self.loaded().get(name) != "active":
                self.switch([name])
                print(f"[spawner] configured and activated {name}")
        if to_activate:
            self.switch(to_activate)
            print(f"[spawner] configured and activated {', '.join(to_activate)}")

    def wait_for_stop(self) -> None:
        while not self.stop_requested:
            time.sleep(0.1)

    def unload(self) -> None:
        """Deactivate (best effort) and unload this spawner's controllers."""
        self.spawning = False
        loaded = self.loaded()
        names = [n for n in self.args.controller_names if n in loaded]  # Ctrl-C may come before all were loaded
        request = SwitchController.Request(deactivate_controllers=[n for n in names if loaded[n] == "active"],
                                           strictness=SwitchController.Request.BEST_EFFORT)
        if request.deactivate_controllers:
            self.call(SwitchController, "switch_controller", request, self.args.switch_timeout + 5.0)
        for name in names:
            self.call(UnloadController, "unload_controller", UnloadController.Request(name=name),
                      self.args.controller_manager_timeout)
        print(f"[spawner] deactivated and unloaded {', '.join(names)}")


def main(args=None):
    argv = rclpy.utilities.remove_ros_args(args if args is not None else sys.argv)[1:]
    options = parse_args(argv)
    if options.param_file:
        try:  # the manager would only log rcl's error for it, at load
            check_params_file(options.param_file)
        except ParamsFileError as error:
            print(f"spawner: {error}", file=sys.stderr)
            sys.exit(1)
    # no rclpy signal handler: Ctrl-C must leave the context usable for --unload-on-kill
    rclpy.init(args=args, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = rclpy.create_node("spawner_" + options.controller_names[0].replace("/", "_"))
    spawner = Spawner(node, options)
    signal.signal(signal.SIGINT, spawner.request_stop)
    signal.signal(signal.SIGTERM, spawner.request_stop)
    code = 0
    try:
        try:
            spawner.run()
            if options.unload_on_kill:
                spawner.wait_for_stop()
        except Interrupted:
            code = 0 if options.unload_on_kill else 130
        except SpawnError as error:
            print(f"spawner: {error}", file=sys.stderr)
            code = 1
        if options.unload_on_kill:
            # the controllers live only as long as this process, also when spawning failed or was cut short
            spawner.unload()
    except SpawnError as error:
        print(f"spawner: {error}", file=sys.stderr)
        code = 1
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    sys.exit(code)


if __name__ == "__main__":
    main()
