"""ControllerInterface and ChainableControllerInterface: the contract with the manager.

Lifecycle (ros2_control): load (`on_init`) -> unconfigured -> `on_configure` -> inactive
-> `on_activate` -> active -> `on_deactivate` -> inactive -> `on_cleanup` -> unconfigured
-> unload (`on_shutdown`). Who calls what:
  on_init, on_configure, on_cleanup, on_shutdown, on_error: the manager's executor thread
    (services, spawner); not real-time; may declare ROS entities on `get_node()`.
  on_activate, on_deactivate: the real-time loop thread, between two cycles (a switch is
    applied there so the loop never sees a half-switched state). Keep them short: reset
    command buffers, take the loaned interfaces; no blocking.
  update(time, period): the real-time loop, active state only, every
    `manager rate / update_rate` cycles (or in the async worker when `is_async`). No
    allocation-heavy work, no blocking, no parameter reads, throttled logs only. Returning
    ERROR or raising deactivates the controller and activates its fallback_controllers.
Parameters: subclasses list `PARAMS` (controller_manager_py.parameters.Param); the manager
validates them once before on_configure into `self.params` (read-only mapping), from the
controller node's parameters (YAML `--params-file`) or the dict given to load_controller.
Interfaces: `command_interface_configuration()`/`state_interface_configuration()` are read
after on_configure; on activation `self.command_interfaces`/`self.state_interfaces` hold
the loaned handles in the order of the configuration's names (`handle.value`).
`get_node()` is the controller's own rclpy Node named after the controller (so `~/commands`
is `/<controller>/commands`), or None without ROS.
"""
from __future__ import annotations

import enum
import logging
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Callable, Dict, List, Mapping, Sequence, Set, Tuple

from ..hardware_interface.handle import CommandInterface, StateInterface
from ..hardware_interface.types import CallbackReturn, State, return_type
from ..parameters import Param, validate


class interface_configuration_type(enum.IntEnum):  # noqa: N801 - the ros2_control name
    ALL = 0
    INDIVIDUAL = 1
    NONE = 2


@dataclass
class InterfaceConfiguration:
    type: interface_configuration_type = interface_configuration_type.NONE
    names: List[str] = field(default_factory=list)


COMMON_PARAMS = (
    Param("update_rate", 0, "controller rate; 0 = the manager's rate", unit="Hz", min=0, user_facing=True),
    Param("is_async", False, "run update() in a worker thread (triggers while busy are skipped)"),
)


class ControllerInterface:
    """Base of every controller. Override the hooks below; see the module docstring."""

    PARAMS: Sequence[Param] = ()

    def __init__(self):
        self.name = ""
        self.params: Mapping = MappingProxyType({})
        self.command_interfaces: List[CommandInterface] = []
        self.state_interfaces: List[StateInterface] = []
        self.lifecycle_state = State.UNCONFIGURED
        self._node = None
        self.robot_description = ""  # URDF text the manager was loaded with ("" before hardware is loaded)
        self._logger = logging.getLogger("controller")
        self.manager_update_rate = 0
        self.introspection: List[Tuple[str, Callable[[], float]]] = []
        self.diagnostic_values: Set[str] = set()   # introspection names also listed in /diagnostics

    # ---- plumbing (called by the manager) --------------------------------------------
    def init(self, name: str, node, logger, manager_update_rate: int) -> CallbackReturn:
        self.name, self._node, self._logger = name, node, logger
        self.manager_update_rate = manager_update_rate
        return self.on_init()

    @classmethod
    def param_schema(cls) -> List[Param]:
        return [*COMMON_PARAMS, *cls.PARAMS]

    def load_params(self, values: Mapping | None) -> None:
        """Validate parameters (from `values`, or the node's parameters). Raises ParameterError."""
        schema = self.param_schema()
        if self._node is not None and values is None:
            from ..parameters import declare_parameters, report_unknown_parameters
            node, declared = self._node, {}
            for p in schema:
                if node.has_parameter(p.name):
                    declared[p.name] = p.validate(node.get_parameter(p.name).value)
                else:
                    declared[p.name] = declare_parameters(node, [p])[p.name]
            self.params = MappingProxyType(declared)
            report_unknown_parameters(node)  # e.g. a typo in the controller's section of the file
        else:
            self.params = validate(schema, values or {}, allow_unknown=True)

    def get_node(self):
        return self._node

    def get_robot_description(self) -> str:
        """The robot description (URDF) the manager's hardware was loaded from, as
        ros2_control's ControllerInterfaceBase::get_robot_description(); read it in
        on_configure or later (e.g. joint limits: manager.joint_limits.limits_from_description)."""
        return self.robot_description

    def register_introspection(self, name: str, getter: Callable[[], float], in_diagnostics: bool = False) -> None:
        """Publish `getter()` as `<controller>.<name>` on ~/introspection_data (call in on_configure).
        Counters of bad input named `refused_*`, `clamped_*` or `limited_*` also appear in
        /diagnostics, WARN when they grew since the previous report; `in_diagnostics` lists any
        other value there too (key `<controller> <name>`, in the "Controllers Activity" status),
        for what a user should see without subscribing to introspection (an estimate, a mode)."""
        self.introspection.append((name, getter))
        if in_diagnostics:
            self.diagnostic_values.add(name)

    def get_logger(self):
        return self._logger

    @property
    def update_rate(self) -> int:
        return int(self.params.get("update_rate", 0)) if self.params else 0

    @property
    def is_async(self) -> bool:
        return bool(self.params.get("is_async", False)) if self.params else False

    def is_chainable(self) -> bool:
        return False

    # ---- hooks --------------------------------------------------------------------------
    def on_init(self) -> CallbackReturn:
        """At load, executor thread. Create nothing heavy; parameters are not read yet."""
        return CallbackReturn.SUCCESS

    def command_interface_configuration(self) -> InterfaceConfiguration:
        return InterfaceConfiguration()

    def state_interface_configuration(self) -> InterfaceConfiguration:
        return InterfaceConfiguration()

    def on_configure(self, previous_state: State) -> CallbackReturn:
        """unconfigured -> inactive, executor thread: `self.params` is ready; create pubs/subs."""
        return CallbackReturn.SUCCESS

    def on_activate(self, previous_state: State) -> CallbackReturn:
        """inactive -> active, loop thread between cycles: interfaces are loaned."""
        return CallbackReturn.SUCCESS

    def on_deactivate(self, previous_state: State) -> CallbackReturn:
        """active -> inactive, loop thread between cycles: interfaces are taken back after."""
        return CallbackReturn.SUCCESS

    def on_cleanup(self, previous_state: State) -> CallbackReturn:
        """inactive -> unconfigured, executor thread: undo on_configure."""
        return CallbackReturn.SUCCESS

    def on_shutdown(self, previous_state: State) -> CallbackReturn:
        """At unload, executor thread."""
        return CallbackReturn.SUCCESS

    def on_error(self, previous_state: State) -> CallbackReturn:
        return CallbackReturn.SUCCESS

    def update(self, time: float, period: float) -> return_type:
        """Real-time: read loaned states, write loaned commands. `time`/`period` in seconds."""
        raise NotImplementedError


class ChainableControllerInterface(ControllerInterface):
    """A controller whose inputs (reference interfaces) another controller can write.

    `on_export_reference_interfaces()` returns interface names; the manager exports them as
    command interfaces `<controller>/<name>` that a preceding controller may claim. When
    claimed (chained mode) `update_reference_from_subscribers` is skipped. Reference handles
    are in `self.reference_interfaces` (same order), holding NaN until written.
    """

    def __init__(self):
        super().__init__()
        self.reference_interfaces: List[CommandInterface] = []
        self.exported_state_interfaces: List[StateInterface] = []
        self.chained_mode = False

    def is_chainable(self) -> bool:
        return True

    def export_reference_interfaces(self) -> List[CommandInterface]:
        self.reference_interfaces = [CommandInterface(self.name, n, owner=self.name)
                                     for n in self.on_export_reference_interfaces()]
        return self.reference_interfaces

    def export_state_interfaces(self) -> List[StateInterface]:
        self.exported_state_interfaces = [StateInterface(self.name, n, float("nan"), owner=self.name)
                                          for n in self.on_export_state_interfaces()]
        return self.exported_state_interfaces

    def on_export_reference_interfaces(self) -> List[str]:
        return []

    def on_export_state_interfaces(self) -> List[str]:
        return []

    def set_chained_mode(self, chained: bool) -> bool:
        self.chained_mode = chained
        return True

    def update_reference_from_subscribers(self, time: float, period: float) -> return_type:
        return return_type.OK

    def update_and_write_commands(self, time: float, period: float) -> return_type:
        raise NotImplementedError

    def update(self, time: float, period: float) -> return_type:
        if not self.chained_mode:
            result = self.update_reference_from_subscribers(time, period)
            if result != return_type.OK:
                return result
        return self.update_and_write_commands(time, period)


def references_by_name(controller: ChainableControllerInterface) -> Dict[str, CommandInterface]:
    return {h.name: h for h in controller.reference_interfaces}
