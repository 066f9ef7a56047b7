"""`ros2py control ...`: a controller manager's services, printed as ros2controlcli prints them."""
from __future__ import annotations

import sys

from ball_balance.cli.errors import CliError
from ball_balance.cli.session import Session, full_node_name

# lifecycle_msgs/State ids
UNCONFIGURED, INACTIVE, ACTIVE = 1, 2, 3

_GREEN, _CYAN, _YELLOW, _MAGENTA, _BLUE, _RED, _END = (
    "\033[92m", "\033[96m", "\033[93m", "\033[95m", "\033[94m", "\033[91m", "\033[0m")


def _color(code: str) -> str:
    """Colour only on a terminal (tests and pipes get plain text)."""
    return code if sys.stdout.isatty() else ""


class ControllerManager:
    """Typed calls to one controller manager (services under its node name)."""

    def __init__(self, session: Session, name: str):
        self.session, self.name = session, full_node_name(name)

    def call(self, service: str, srv_name: str, **fields):
        import importlib

        srv = getattr(importlib.import_module("controller_manager_msgs.srv"), srv_name)
        full = f"{self.name}/{service}"
        if not self.session.spin_until(
                lambda: any(n == full for n, _ in self.session.node.get_service_names_and_types()),
                self.session.spin_time_s):
            raise CliError(f"controller manager '{self.name}' not found: service {full} is not available "
                           f"(waited {self.session.spin_time_s:.1f} s; set it with -c)")
        return self.session.call(srv, full, srv.Request(**fields), timeout_s=max(self.session.spin_time_s, 10.0))

    def controllers(self):
        return list(self.call("list_controllers", "ListControllers").controller)

    def state_of(self, controller: str) -> str:
        for c in self.controllers():
            if c.name == controller:
                return c.state
        raise CliError(f"controller '{controller}' is not loaded in {self.name}")

    def switch(self, activate=(), deactivate=(), strict: bool = True, asap: bool = False,
               timeout_s: float = 5.0):
        from builtin_interfaces.msg import Duration

        strictness = 2 if strict else 1  # SwitchController.Request.STRICT / BEST_EFFORT
        response = self.call("switch_controller", "SwitchController", activate_controllers=list(activate),
                             deactivate_controllers=list(deactivate), strictness=strictness,
                             activate_asap=asap, timeout=Duration(sec=int(timeout_s),
                                                                  nanosec=int(timeout_s % 1 * 1e9)))
        if not response.ok:
            detail = f": {response.message}" if response.message else ", check controller_manager logs"
            raise CliError(f"Error switching controllers{detail}")
        return response

    def expect_ok(self, service: str, srv_name: str, controller: str, what: str) -> None:
        if not self.call(service, srv_name, name=controller).ok:
            raise CliError(f"Error {what} controller {controller}, check controller_manager logs")


def _manager(args, session: Session) -> ControllerManager:
    return ControllerManager(session, args.controller_manager)


def cmd_list_controllers(args) -> int:
    with Session(args.spin_time) as session:
        controllers = _manager(args, session).controllers()
    if not controllers:
        print("No controllers are currently loaded!")
        return 0
    w_name = max(len(c.name) for c in controllers)
    w_type = max(len(c.type) for c in controllers)
    w_state = max(len(c.state) for c in controllers)
    colors = {"active": _GREEN, "inactive": _CYAN, "unconfigured": _YELLOW}
    end = _color(_END)
    for c in controllers:
        color = _color(colors.get(c.state, ""))
        print(f"{color}{c.name:<{w_name}}{end} {c.type:<{w_type}}  {color}{c.state:<{w_state}}{end}")
        if args.verbose:
            print(f"\tupdate_rate: {c.update_rate} Hz")
            print(f"\tis_async: {bool(c.is_async)}")
        exported = args.reference_interfaces or args.exported_interfaces
        sections = [
            (args.claimed_interfaces, "claimed interfaces", c.claimed_interfaces),
            (args.required_command_interfaces, "required command interfaces", c.required_command_interfaces),
            (args.required_state_interfaces, "required state interfaces", c.required_state_interfaces),
            (args.chained_interfaces, "chained to interfaces",
             [f"{ref:20s}" for conn in c.chain_connections for ref in conn.reference_interfaces]),
            (exported, "exported reference interfaces", c.reference_interfaces),
            (exported, "exported state interfaces", c.exported_state_interfaces),
        ]
        for wanted, title, items in sections:
            if wanted or args.verbose:
                print(f"\t{title}:")
                for item in items:
                    print(f"\t\t{item}")
    return 0


def _interface_flags(interface, claimed: bool = True) -> str:
    available = (f"{_color(_BLUE)}[available]{_color(_END)}" if interface.is_available
                 else f"{_color(_YELLOW)}[unavailable]{_color(_END)}")
    if not claimed:
        return available
    return available + (f" {_color(_BLUE)}[claimed]{_color(_END)}" if interface.is_claimed else " [unclaimed]")


def _data_type(interface, verbose: bool) -> str:
    """' [double]' with -v, as ros2controlcli prints a hardware interface's data type."""
    return f" [{interface.data_type}]" if verbose else ""


def cmd_list_hardware_components(args) -> int:
    with Session(args.spin_time) as session:
        components = list(_manager(args, session).call("list_hardware_components", "ListHardwareComponents").component)
    colors = {UNCONFIGURED: _YELLOW, INACTIVE: _MAGENTA, ACTIVE: _GREEN}
    end = _color(_END)
    for index, component in enumerate(components, start=1):
        color = _color(colors.get(component.state.id, _RED))
        print(f"Hardware Component {index}\n\tname: {color}{component.name}{end}\n\ttype: {component.type}")
        print(f"\tplugin name: {component.plugin_name or component.class_type}")
        print(f"\tstate: id={component.state.id} label={color}{component.state.label}{end}")
        print(f"\tread/write rate: {component.rw_rate} Hz")
        print(f"\tis_async: {bool(component.is_async)}")
        print("\tcommand interfaces")
        for interface in component.command_interfaces:
            print(f"\t\t{interface.name}{_data_type(interface, args.verbose)} {_interface_flags(interface)}")
        if args.verbose:
            print("\tstate interfaces")
            for interface in component.state_interfaces:
                print(f"\t\t{interface.name}{_data_type(interface, True)} {_interface_flags(interface, claimed=False)}")
    return 0


def cmd_list_hardware_interfaces(args) -> int:
    with Session(args.spin_time) as session:
        response = _manager(args, session).call("list_hardware_interfaces", "ListHardwareInterfaces")
    print("command interfaces")
    for interface in sorted(response.command_interfaces, key=lambda i: i.name):
        # ros2controlcli prints an unavailable command interface as unclaimed, whatever it says
        flags = (_interface_flags(interface) if interface.is_available
                 else f"{_interface_flags(interface, claimed=False)} [unclaimed]")
        print(f"\t{interface.name}{_data_type(interface, args.verbose)} {flags}")
    print("state interfaces")
    for interface in sorted(response.state_interfaces, key=lambda i: i.name):
        print(f"\t{interface.name}{_data_type(interface, args.verbose)}")
    return 0


def switch_outcome(before: dict, after: dict, activate, deactivate):
    """(done, skipped) parts of a switch request, from the controllers' states before and after.

    A controller both deactivated and activated (a restart) is active before and after."""
    restart = set(activate) & set(deactivate)
    done, skipped = [], []
    for name in deactivate:
        ok = before.get(name) == "active" and (after.get(name) != "active" or name in restart)
        (done if ok else skipped).append(f"deactivate {name}")
    for name in activate:
        ok = after.get(name) == "active" and (before.get(name) != "active" or name in restart)
        (done if ok else skipped).append(f"activate {name}")
    return done, skipped


def cmd_switch_controllers(args) -> int:
    if not args.activate and not args.deactivate:
        raise CliError("nothing to switch: give --activate and/or --deactivate")
    with Session(args.spin_time) as session:
        manager = _manager(args, session)
        before = {c.name: c.state for c in manager.controllers()}
        response = manager.switch(args.activate, args.deactivate, strict=not args.best_effort,
                                  asap=args.activate_asap, timeout_s=args.switch_timeout)
        after = {c.name: c.state for c in manager.controllers()}
    # a best-effort switch "succeeds" even when it skipped every part: say what happened
    done, skipped = switch_outcome(before, after, args.activate, args.deactivate)
    reason = response.message if response.message and response.message != "Switch successful" else ""
    if not done:
        raise CliError(f"switch changed nothing ({', '.join(skipped)}: not done)"
                       + (f": {reason}" if reason else ""))
    if skipped:
        print(f"{', '.join(skipped)}: skipped" + (f" ({reason})" if reason else ""), file=sys.stderr)
    print("Successfully switched controllers")
    return 0


def _set_state(manager: ControllerManager, name: str, target: str) -> None:
    """Bring a loaded controller to 'inactive' or 'active', as ros2controlcli does."""
    state = manager.state_of(name)
    if state == target:
        print(f"{name} is already {state}")
        return
    if target == "inactive":
        if state == "unconfigured":
            manager.expect_ok("configure_controller", "ConfigureController", name, "configuring")
            print(f"Successfully configured {name}")
        elif state == "active":
            manager.switch(deactivate=[name])
            print(f"Successfully deactivated {name}")
        else:
            raise CliError(f"cannot configure {name}: it is {state}, not unconfigured or active")
    else:
        if state == "unconfigured":
            manager.expect_ok("configure_controller", "ConfigureController", name, "configuring")
            state = "inactive"
        if state != "inactive":
            raise CliError(f"cannot activate {name}: it is {state}, not inactive")
        manager.switch(activate=[name])
        print(f"Successfully activated {name}")


def cmd_load_controller(args) -> int:
    with Session(args.spin_time) as session:
        manager = _manager(args, session)
        manager.expect_ok("load_controller", "LoadController", args.controller_name, "loading")
        print(f"Successfully loaded controller {args.controller_name}")
        if args.set_state:
            _set_state(manager, args.controller_name, args.set_state)
    return 0


def cmd_set_controller_state(args) -> int:
    with Session(args.spin_time) as session:
        _set_state(_manager(args, session), args.controller_name, args.state)
    return 0


def cmd_unload_controller(args) -> int:
    with Session(args.spin_time) as session:
        _manager(args, session).expect_ok("unload_controller", "UnloadController", args.controller_name,
                                          "unloading")
    print(f"Successfully unloaded controller {args.controller_name}")
    return 0


def cmd_list_controller_types(args) -> int:
    with Session(args.spin_time) as session:
        response = _manager(args, session).call("list_controller_types", "ListControllerTypes")
    for type_name, base_class in zip(response.types, response.base_classes, strict=False):
        print(f"{type_name:70s} {base_class}")
    return 0


def cmd_configure_controller(args) -> int:
    with Session(args.spin_time) as session:
        _manager(args, session).expect_ok("configure_controller", "ConfigureController", args.controller_name,
                                          "configuring")
    print(f"Successfully configured {args.controller_name}")
    return 0


_HARDWARE_STATES = {"unconfigured": UNCONFIGURED, "inactive": INACTIVE, "active": ACTIVE}


def cmd_set_hardware_component_state(args) -> int:
    from lifecycle_msgs.msg import State

    target = State(id=_HARDWARE_STATES[args.state], label=args.state)
    with Session(args.spin_time) as session:
        response = _manager(args, session).call("set_hardware_component_state", "SetHardwareComponentState",
                                                name=args.hardware_component_name, target_state=target)
    if not response.ok:
        raise CliError(f"Error setting hardware component {args.hardware_component_name} to {args.state} "
                       f"(it is {response.state.label or 'unknown'}), check controller_manager logs")
    print(f"Successfully set {args.hardware_component_name} to state {response.state.label or args.state}")
    return 0
