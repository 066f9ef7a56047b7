"""Resource manager: hardware components, their interfaces, claiming, lifecycle, read/write.

Loading is all-or-nothing: `ResourceManager.from_description()` parses, imports and
initialises every component and raises ResourceError (one line) on the first problem,
so a bad description never replaces a working one. Command interfaces are claimed
exclusively (`claim`); a second claim raises ResourceError naming the holder.
"""
from __future__ import annotations

import logging
import time as _time
from typing import Dict, List, Optional, Tuple

from ..hardware_interface.component import HardwareComponentInterface
from ..hardware_interface.handle import CommandInterface, StateInterface
from ..hardware_interface.types import CallbackReturn, HardwareInfo, State, return_type
from ..hardware_interface.urdf import DescriptionError, parse_control_resources
from ..plugins import HARDWARE_GROUP, PluginError, load_class
from .async_handler import AsyncHandler
from .joint_limits import HandleLimiter
from .statistics import PeriodicityStats
from .throttle import Throttle


class ResourceError(RuntimeError):
    """A hardware or claiming problem (the message names the component or interface)."""


class Component:
    """One loaded hardware component and the manager's bookkeeping around it."""

    def __init__(self, info: HardwareInfo, plugin: HardwareComponentInterface, manager_rate: int,
                 enforce_command_limits: bool = True, logger=None):
        self.info, self.plugin = info, plugin
        self.name = info.name
        self.state = State.UNCONFIGURED
        self.limiter = HandleLimiter(info.limits if enforce_command_limits else {}, plugin.command_handles,
                                     plugin.state_handles, logger, info.name)
        rate = info.rw_rate if 0 < info.rw_rate <= manager_rate else manager_rate
        self.divisor = max(1, round(manager_rate / rate)) if rate else 1
        self.rw_rate = manager_rate // self.divisor if manager_rate else 0
        self.read_stats, self.write_stats = PeriodicityStats(), PeriodicityStats()
        self.async_handler: Optional[AsyncHandler] = None
        self.read_errors = self.write_errors = 0
        self.transitioning = False  # a lifecycle transition runs in the executor: the loop leaves it alone
        self._last_read = self._last_write = None

    @property
    def kind(self) -> str:
        return getattr(self.plugin, "kind", self.info.type)

    def read_once(self, time: float, period: float) -> return_type:
        start = _time.monotonic()
        result = self.plugin.read(time, period)
        self.read_stats.add(start, _time.monotonic())
        return result

    def write_once(self, time: float, period: float) -> return_type:
        self.limiter.enforce(period)
        start = _time.monotonic()
        result = self.plugin.write(time, period)
        self.write_stats.add(start, _time.monotonic())
        return result

    def data_age(self, now: float) -> float:
        """Seconds since the async worker last finished a read/write (NaN when not async)."""
        handler = self.async_handler
        return now - handler.last_finish if handler is not None else float("nan")

    def cycle_async(self, time: float, period: float) -> return_type:
        """Async worker body: read, then write when active."""
        result = self.read_once(time, period)
        if result == return_type.OK and self.state == State.ACTIVE:
            result = self.write_once(time, period)
        return result


# transitions (from, to) -> hook names in order, as ros2_control's lifecycle
_PATHS = {
    (State.UNCONFIGURED, State.INACTIVE): ("on_configure",),
    (State.UNCONFIGURED, State.ACTIVE): ("on_configure", "on_activate"),
    (State.INACTIVE, State.ACTIVE): ("on_activate",),
    (State.INACTIVE, State.UNCONFIGURED): ("on_cleanup",),
    (State.ACTIVE, State.INACTIVE): ("on_deactivate",),
    (State.ACTIVE, State.UNCONFIGURED): ("on_deactivate", "on_cleanup"),
}
_AFTER = {"on_configure": State.INACTIVE, "on_activate": State.ACTIVE, "on_deactivate": State.INACTIVE,
          "on_cleanup": State.UNCONFIGURED, "on_shutdown": State.FINALIZED}


class ResourceManager:
    def __init__(self, components: List[Component], logger=None, clock=None):
        self.components: Dict[str, Component] = {c.name: c for c in components}
        self.logger = logger or logging.getLogger("resource_manager")
        self.throttle = Throttle(self.logger)
        self.state_interfaces: Dict[str, StateInterface] = {}
        self.command_interfaces: Dict[str, CommandInterface] = {}
        self.interface_owner: Dict[str, str] = {}  # interface -> component or controller
        self.claimed: Dict[str, str] = {}  # command interface -> controller
        self.controller_owner_states: Dict[str, State] = {}  # exported by controllers
        self.clock_component: Optional[Component] = None
        self._clock = clock or _time.monotonic
        for comp in components:
            for name, handle in comp.plugin.state_handles.items():
                self._add(self.state_interfaces, name, handle, comp.name)
            for name, handle in comp.plugin.command_handles.items():
                self._add(self.command_interfaces, name, handle, comp.name)
            if comp.plugin.provides_clock:
                if self.clock_component is not None:
                    raise ResourceError(f"both '{self.clock_component.name}' and '{comp.name}' provide the clock")
                self.clock_component = comp

    def _add(self, table: Dict, name: str, handle, owner: str) -> None:
        if name in table:
            raise ResourceError(f"interface '{name}' exported by both '{self.interface_owner[name]}' and '{owner}'")
        table[name] = handle
        self.interface_owner[name] = owner

    @classmethod
    def from_description(cls, urdf: str, manager_rate: int, node=None, logger=None,
                         enforce_command_limits: bool = True, require_limits: bool = True) -> ResourceManager:
        """require_limits: refuse revolute/prismatic joints without a URDF <limit>."""
        logger = logger or logging.getLogger("resource_manager")
        try:
            infos = parse_control_resources(urdf, require_limits=require_limits and enforce_command_limits)
        except DescriptionError as error:
            raise ResourceError(str(error)) from None
        components = []
        for info in infos:
            try:
                plugin = load_class(HARDWARE_GROUP, info.hardware_plugin_name)()
            except PluginError as error:
                raise ResourceError(f"hardware '{info.name}': {error}") from None
            plugin._attach(node, logger)
            try:
                result = plugin.on_init(info)
            except Exception as error:  # noqa: BLE001 - a plugin bug is a load failure
                raise ResourceError(f"hardware '{info.name}': on_init raised {error!r}") from None
            if result != CallbackReturn.SUCCESS:
                raise ResourceError(f"hardware '{info.name}' ({info.hardware_plugin_name}): on_init failed")
            plugin.lifecycle_state = State.UNCONFIGURED
            if info.rw_rate and manager_rate and manager_rate % info.rw_rate:
                used = manager_rate // max(1, round(manager_rate / info.rw_rate))
                logger.warning(f"hardware '{info.name}': rw_rate {info.rw_rate} Hz is not a divisor of "
                               f"{manager_rate} Hz; using {used} Hz")
            components.append(Component(info, plugin, manager_rate, enforce_command_limits, logger))
        return cls(components, logger)

    # ---- availability and claiming ---------------------------------------------------------
    def owner_state(self, name: str) -> State:
        owner = self.components.get(self.interface_owner.get(name, ""))
        return owner.state if owner is not None else self.controller_owner_states.get(name, State.UNKNOWN)

    def state_available(self, name: str) -> bool:
        return name in self.state_interfaces and self.owner_state(name) in (State.INACTIVE, State.ACTIVE)

    def command_available(self, name: str) -> bool:
        return name in self.command_interfaces and self.owner_state(name) in (State.INACTIVE, State.ACTIVE)

    def claim(self, name: str, controller: str) -> CommandInterface:
        if name not in self.command_interfaces:
            raise ResourceError(f"command interface '{name}' does not exist")
        holder = self.claimed.get(name)
        if holder is not None and holder != controller:
            raise ResourceError(f"command interface '{name}' is already claimed by controller '{holder}'")
        self.claimed[name] = controller
        return self.command_interfaces[name]

    def release(self, name: str, controller: str) -> None:
        if self.claimed.get(name) == controller:
            del self.claimed[name]

    def add_controller_interfaces(self, controller: str, references: List[CommandInterface],
                                  states: List[StateInterface], state: State) -> None:
        for h in references:
            self._add(self.command_interfaces, h.name, h, controller)
        for h in states:
            self._add(self.state_interfaces, h.name, h, controller)
        self.set_controller_interfaces_state(controller, state)

    def set_controller_interfaces_state(self, controller: str, state: State) -> None:
        for name, owner in list(self.interface_owner.items()):
            if owner == controller:
                self.controller_owner_states[name] = state

    def remove_controller_interfaces(self, controller: str) -> None:
        for name in [n for n, o in self.interface_owner.items() if o == controller]:
            self.command_interfaces.pop(name, None)
            self.state_interfaces.pop(name, None)
            self.interface_owner.pop(name, None)
            self.controller_owner_states.pop(name, None)

    def interfaces_of(self, component: str) -> Tuple[List[str], List[str]]:
        comp = self.components[component]
        return list(comp.plugin.command_handles), list(comp.plugin.state_handles)

    # ---- hardware lifecycle (executor thread) ---------------------------------------------
    def set_component_state(self, name: str, target: State) -> State:
        """Drive component `name` to `target` through the lifecycle; returns the reached state."""
        comp = self.components.get(name)
        if comp is None:
            raise ResourceError(f"hardware component '{name}' does not exist")
        if comp.state == target or comp.state == State.FINALIZED:
            return comp.state
        hooks = ("on_shutdown",) if target == State.FINALIZED else _PATHS.get((comp.state, target))
        if hooks is None:
            raise ResourceError(f"hardware '{name}': no transition {comp.state.label} -> {target.label}")
        for hook in hooks:
            previous = comp.state
            try:
                result = getattr(comp.plugin, hook)(previous)
            except Exception as error:  # noqa: BLE001
                self.logger.error(f"hardware '{name}': {hook} raised {error!r}")
                result = CallbackReturn.ERROR
            if result == CallbackReturn.SUCCESS:
                comp.state = _AFTER[hook]
                if hook == "on_activate":
                    comp.limiter.reset()
            elif result == CallbackReturn.ERROR:
                self._to_error(comp)
                break
            else:
                self.logger.warning(f"hardware '{name}': {hook} failed; stays {comp.state.label}")
                break
            comp.plugin.lifecycle_state = comp.state
        self._update_async(comp)
        return comp.state

    def _to_error(self, comp: Component) -> None:
        try:
            ok = comp.plugin.on_error(comp.state) == CallbackReturn.SUCCESS
        except Exception:  # noqa: BLE001
            ok = False
        comp.state = State.UNCONFIGURED if ok else State.FINALIZED
        comp.plugin.lifecycle_state = comp.state

    def _update_async(self, comp: Component) -> None:
        running = comp.state in (State.INACTIVE, State.ACTIVE)
        if comp.info.is_async and running and comp.async_handler is None:
            params = comp.info.async_params
            comp.async_handler = AsyncHandler(comp.name, comp.cycle_async,
                                              detached=params.scheduling_policy == "detached",
                                              rate_hz=comp.rw_rate or 100, clock=self._clock,
                                              thread_priority=params.thread_priority,
                                              affinity=params.affinity)
        elif not running and comp.async_handler is not None:
            comp.async_handler.stop()
            comp.async_handler = None

    def activate_all(self) -> None:
        for name in self.components:
            self.set_component_state(name, State.ACTIVE)

    def shutdown(self) -> None:
        for name, comp in self.components.items():
            if comp.state == State.ACTIVE:
                self.set_component_state(name, State.INACTIVE)
            self.set_component_state(name, State.FINALIZED)
            self._update_async(comp)

    # ---- real-time: read and write ----------------------------------------------------------
    def read(self, time: float, period: float, cycle: int, failed: List[str]) -> None:
        """Read every inactive/active component due this cycle; append failing names to `failed`."""
        for comp in self.components.values():
            state = comp.state
            if (state != State.ACTIVE and state != State.INACTIVE) or cycle % comp.divisor or comp.transitioning:
                continue
            handler = comp.async_handler
            try:
                if handler is not None:
                    skipped = handler.skipped
                    result = handler.trigger(time, period * comp.divisor)
                    if handler.skipped != skipped and comp.info.async_params.print_warnings:
                        self.throttle.warn(f"{comp.name}.async", f"hardware '{comp.name}': its async read/write "
                                           f"is still running; cycle skipped ({handler.skipped} so far)")
                else:
                    result = comp.read_once(time, period * comp.divisor)
            except Exception as error:  # noqa: BLE001 - a component bug is a read error
                self.logger.error(f"hardware '{comp.name}': read raised {error!r}")
                result = return_type.ERROR
            if result != return_type.OK:
                comp.read_errors += 1
                failed.append(comp.name)

    def write(self, time: float, period: float, cycle: int, failed: List[str]) -> None:
        for comp in self.components.values():
            if (comp.state != State.ACTIVE or comp.async_handler is not None or cycle % comp.divisor
                    or comp.kind == "sensor" or comp.transitioning):
                continue
            try:
                result = comp.write_once(time, period * comp.divisor)
            except Exception as error:  # noqa: BLE001
                self.logger.error(f"hardware '{comp.name}': write raised {error!r}")
                result = return_type.ERROR
            if result != return_type.OK:
                comp.write_errors += 1
                failed.append(comp.name)

    def handle_failure(self, name: str) -> None:
        """After a read/write error: the component goes through on_error (loop thread)."""
        comp = self.components[name]
        if comp.state in (State.ACTIVE, State.INACTIVE):
            self._to_error(comp)
            self._update_async(comp)
