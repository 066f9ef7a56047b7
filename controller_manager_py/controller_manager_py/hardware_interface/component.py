"""Hardware component bases: SystemInterface, ActuatorInterface, SensorInterface.

These docstrings are the contract between the controller manager and a component.

Lifecycle (ids of lifecycle_msgs/State, physical meaning as in ros2_control):
  unconfigured: loaded, `on_init` done, no communication with the device;
  inactive: communication up, states are read (`read()` runs), commands are NOT written;
  active: `read()` and `write()` run every cycle, commands reach the device;
  finalized: shut down, never used again.
The manager (its resource manager) calls the hooks; `set_hardware_component_state` (the
service) drives the same transitions. Lifecycle hooks run in the manager's executor
thread, never in the real-time loop, and may block briefly (opening a device, a socket).

Interfaces are exported automatically from the description (`info.joints/sensors/gpios`,
their `<state_interface>`/`<command_interface>` tags, `initial_value` honoured). A
component reads and writes them through `get_state(name)`, `set_state(name, v)`,
`get_command(name)`, `set_command(name, v)` (name = "joint/interface"), or, cheaper in
`read()`/`write()`, through the handle objects in `self.state_handles` /
`self.command_handles` (`handle.value`). Extra interfaces the description does not list
come from `export_unlisted_state_interfaces()` / `export_unlisted_command_interfaces()`.
A command interface holds NaN ("no command yet") until a controller writes it.

ROS access: `self.get_node()` returns the controller manager's rclpy Node (create
publishers, timers, services on it; its executor runs them, outside the real-time loop),
or None when the manager runs without ROS (pure tests). It is available from `on_init`
onward. Do not block in callbacks created there.

Clock: a component that simulates time sets the class attribute `provides_clock = True`
and implements `now() -> float` (seconds). The manager then uses `now()` as the time
given to read/update/write and to controllers (message stamps), instead of the wall
clock; only one component may provide the clock. Publishing `/clock` is the component's
job (it has the node).

Time arguments: `time` is seconds (float, the manager's clock), `period` seconds since
the previous call of this component's read (or write).
"""
from __future__ import annotations

from typing import Callable, Dict, List, Optional, Sequence, Tuple

from .handle import CommandInterface, StateInterface
from .types import CallbackReturn, HardwareInfo, State, return_type


class HardwareComponentInterface:
    """Common base of the three component kinds (use one of the subclasses)."""

    provides_clock = False
    """True when this component owns the clock (simulated time): see the module docstring."""

    def __init__(self):
        self.info: Optional[HardwareInfo] = None
        self.state_handles: Dict[str, StateInterface] = {}
        self.command_handles: Dict[str, CommandInterface] = {}
        self.introspection: List[Tuple[str, Callable[[], float]]] = []
        self._node = None
        self._logger = None
        self.lifecycle_state = State.UNKNOWN

    # ---- set by the manager before on_init (not for subclasses to call) -----------------
    def _attach(self, node, logger) -> None:
        self._node, self._logger = node, logger

    def get_node(self):
        """The manager's rclpy Node (None without ROS). Valid from on_init onward."""
        return self._node

    def get_logger(self):
        """A logger (rclpy's when there is a node, else Python logging)."""
        return self._logger

    def get_name(self) -> str:
        return self.info.name if self.info else ""

    # ---- lifecycle hooks: executor thread, not real-time -------------------------------
    def on_init(self, info: HardwareInfo) -> CallbackReturn:
        """Called once at load (unknown -> unconfigured). Validate `info`, keep parameters.

        The base stores `info` and creates the handles from it: call `super().on_init(info)`
        first and return FAILURE (after logging why) when the description is unusable.
        """
        self.info = info
        for comp in info.components():
            for itf in comp.state_interfaces:
                value = itf.initial_value if itf.initial_value is not None else float("nan")
                self.state_handles[f"{comp.name}/{itf.name}"] = StateInterface(comp.name, itf.name, value, info.name)
            for itf in comp.command_interfaces:
                self.command_handles[f"{comp.name}/{itf.name}"] = CommandInterface(
                    comp.name, itf.name, owner=info.name)
        for prefix, itf in self.export_unlisted_state_interfaces():
            self.state_handles[f"{prefix}/{itf}"] = StateInterface(prefix, itf, float("nan"), info.name)
        for prefix, itf in self.export_unlisted_command_interfaces():
            self.command_handles[f"{prefix}/{itf}"] = CommandInterface(prefix, itf, owner=info.name)
        return CallbackReturn.SUCCESS

    def export_unlisted_state_interfaces(self) -> Sequence[Tuple[str, str]]:
        """Extra (prefix, interface) state interfaces not in the description. Called in on_init."""
        return ()

    def export_unlisted_command_interfaces(self) -> Sequence[Tuple[str, str]]:
        """Extra (prefix, interface) command interfaces not in the description."""
        return ()

    def on_configure(self, previous_state: State) -> CallbackReturn:
        """unconfigured -> inactive: open communication; register introspection variables."""
        return CallbackReturn.SUCCESS

    def on_cleanup(self, previous_state: State) -> CallbackReturn:
        """inactive -> unconfigured: close communication."""
        return CallbackReturn.SUCCESS

    def on_activate(self, previous_state: State) -> CallbackReturn:
        """inactive -> active: enable motion. Commands are written from the next cycle."""
        return CallbackReturn.SUCCESS

    def on_deactivate(self, previous_state: State) -> CallbackReturn:
        """active -> inactive: stop motion; reads continue."""
        return CallbackReturn.SUCCESS

    def on_shutdown(self, previous_state: State) -> CallbackReturn:
        """any -> finalized: release everything (also called when the manager exits)."""
        return CallbackReturn.SUCCESS

    def on_error(self, previous_state: State) -> CallbackReturn:
        """After a hook returned ERROR (executor thread) or read/write failed (loop thread, after
        the controllers using this component were deactivated): SUCCESS -> unconfigured, else
        finalized. Keep it short and non-blocking."""
        return CallbackReturn.SUCCESS

    # ---- mode switches (ros2_control semantics) -----------------------------------------
    def prepare_command_mode_switch(self, start_interfaces: List[str], stop_interfaces: List[str]) -> return_type:
        """Executor thread, before a controller switch: may the switch happen? Not real-time."""
        return return_type.OK

    def perform_command_mode_switch(self, start_interfaces: List[str], stop_interfaces: List[str]) -> return_type:
        """Real-time loop, between cycles: apply the switch. Must not block."""
        return return_type.OK

    # ---- real-time hooks ----------------------------------------------------------------
    def read(self, time: float, period: float) -> return_type:
        """Real-time loop (or the component's async thread), in inactive and active states.

        Update the state interfaces from the device. Must not allocate heavily, block
        (except with hardware_synchronization.expect_blocking_read_write) or log unthrottled.
        ERROR deactivates every controller using this component and moves it to on_error.
        """
        return return_type.OK

    def write(self, time: float, period: float) -> return_type:
        """Real-time loop (or async thread), active state only: send the command interfaces."""
        return return_type.OK

    def now(self) -> float:
        """Simulated time in seconds (only called when provides_clock is True)."""
        raise NotImplementedError

    # ---- helpers for subclasses ---------------------------------------------------------
    def get_state(self, name: str) -> float:
        return self.state_handles[name].value

    def set_state(self, name: str, value: float) -> None:
        self.state_handles[name].value = value

    def get_command(self, name: str) -> float:
        return self.command_handles[name].value

    def set_command(self, name: str, value: float) -> None:
        self.command_handles[name].value = value

    def register_introspection(self, name: str, getter: Callable[[], float]) -> None:
        """Publish `getter()` as `<component>.<name>` on ~/introspection_data (call in on_configure)."""
        self.introspection.append((name, getter))


class SystemInterface(HardwareComponentInterface):
    """Multi-joint hardware with command and state interfaces (a robot arm, a simulator)."""

    kind = "system"


class ActuatorInterface(HardwareComponentInterface):
    """One joint with command and state interfaces."""

    kind = "actuator"


class SensorInterface(HardwareComponentInterface):
    """State interfaces only; `write()` is never called."""

    kind = "sensor"
