"""Planning (executor thread) and applying (loop thread, between cycles) a controller switch.

Planning checks everything that can fail: names, states, interface existence and
availability, exclusive claims (against active controllers and within the request),
chained references, the hardware's prepare_command_mode_switch. With STRICT any problem
fails the whole request; with BEST_EFFORT the offending controllers are dropped and the
rest goes ahead. Applying then only runs the lifecycle hooks and moves the handles.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Dict, List

from ..hardware_interface.types import CallbackReturn, State, return_type
from .resource_manager import ResourceError

if TYPE_CHECKING:
    from .controller_manager import ControllerManager
    from .controller_spec import ControllerSpec

BEST_EFFORT, STRICT, AUTO, FORCE_AUTO = 1, 2, 3, 4


class SwitchError(RuntimeError):
    """The switch cannot be done (the message says which controller and why)."""


@dataclass
class SwitchPlan:
    deactivate: List[ControllerSpec] = field(default_factory=list)
    activate: List[ControllerSpec] = field(default_factory=list)
    start_interfaces: List[str] = field(default_factory=list)
    stop_interfaces: List[str] = field(default_factory=list)
    activate_asap: bool = True
    messages: List[str] = field(default_factory=list)

    @property
    def empty(self) -> bool:
        return not self.deactivate and not self.activate


def plan_switch(cm: ControllerManager, activate: List[str], deactivate: List[str], strictness: int,
                activate_asap: bool = True) -> SwitchPlan:
    if strictness in (AUTO, FORCE_AUTO):
        activate, deactivate = _resolve(cm, list(activate), list(deactivate), strictness == FORCE_AUTO)
    strict = strictness != BEST_EFFORT
    plan = SwitchPlan(activate_asap=activate_asap)

    def problem(message: str) -> None:
        if strict:
            raise SwitchError(message)
        plan.messages.append(message)
        cm.logger.warning(f"switch (best effort): {message}; skipped")

    deact: List[ControllerSpec] = []
    for name in dict.fromkeys(deactivate):
        spec = cm.controllers.get(name)
        if spec is None:
            problem(f"cannot deactivate '{name}': controller is not loaded")
        elif spec.state != State.ACTIVE:
            problem(f"cannot deactivate '{name}': controller is {spec.state.label}, not active")
        else:
            deact.append(spec)
    leaving = {s.name for s in deact}
    claimed_after = {itf: ctl for itf, ctl in list(cm.rm.claimed.items()) if ctl not in leaving}
    act: List[ControllerSpec] = []
    for name in dict.fromkeys(activate):
        spec = cm.controllers.get(name)
        if spec is None:
            problem(f"cannot activate '{name}': controller is not loaded")
            continue
        if spec.state == State.ACTIVE and name not in leaving:
            problem(f"cannot activate '{name}': controller is already active")
            continue
        if spec.state not in (State.INACTIVE, State.ACTIVE):
            problem(f"cannot activate '{name}': controller is {spec.state.label}, configure it first")
            continue
        reason = _interface_problem(cm, spec, claimed_after, leaving, activate)
        if reason:
            problem(f"cannot activate '{name}': {reason}")
            continue
        for itf in spec.command_names:
            claimed_after[itf] = name
        act.append(spec)
    # a controller whose reference interfaces stay claimed by an active controller must stay active
    for spec in list(deact):
        users = {claimed_after[i] for i in list(cm.rm.command_interfaces) if cm.rm.interface_owner.get(i) == spec.name
                 and i in claimed_after}
        if users:
            problem(f"cannot deactivate '{spec.name}': its reference interfaces are used by {sorted(users)}")
            deact.remove(spec)
    plan.deactivate, plan.activate = deact, act
    plan.stop_interfaces = [i for s in deact for i in s.command_names]
    plan.start_interfaces = [i for s in act for i in s.command_names]
    if not plan.empty:
        for comp in cm.rm.components.values():
            mine = set(comp.plugin.command_handles)
            start = [i for i in plan.start_interfaces if i in mine]
            stop = [i for i in plan.stop_interfaces if i in mine]
            if (start or stop) and comp.plugin.prepare_command_mode_switch(start, stop) != return_type.OK:
                raise SwitchError(f"hardware '{comp.name}' refused the command mode switch")
    return plan


def _resolve(cm: ControllerManager, activate: List[str], deactivate: List[str], force: bool):
    """AUTO: add the chained controllers an activation needs and the ones a deactivation
    strands; FORCE_AUTO also deactivates the holders of interfaces an activation claims."""
    owner = cm.rm.interface_owner
    pending = list(activate)
    while pending:
        spec = cm.controllers.get(pending.pop())
        for itf in spec.command_names if spec is not None else ():
            target = owner.get(itf)
            if target in cm.controllers and target not in activate and cm.controllers[target].state != State.ACTIVE:
                activate.append(target)
                pending.append(target)
    if force:
        for name in activate:
            spec = cm.controllers.get(name)
            for itf in spec.command_names if spec is not None else ():
                holder = cm.rm.claimed.get(itf)
                if holder is not None and holder != name and holder not in deactivate:
                    deactivate.append(holder)
    pending = list(deactivate)
    while pending:
        name = pending.pop()
        for itf, holder in list(cm.rm.claimed.items()):
            if owner.get(itf) == name and holder not in deactivate:
                deactivate.append(holder)
                pending.append(holder)
    return activate, deactivate


def _interface_problem(cm, spec, claimed_after: Dict[str, str], leaving, activating: List[str]) -> str:
    rm = cm.rm
    for itf in spec.command_names:
        if itf not in rm.command_interfaces:
            return f"command interface '{itf}' does not exist"
        owner = rm.interface_owner.get(itf)
        if owner in cm.controllers:  # a reference interface: its controller must be (getting) active
            target = cm.controllers[owner]
            if owner in leaving or (target.state != State.ACTIVE and owner not in activating):
                return f"reference interface '{itf}' needs controller '{owner}' active"
        elif not rm.command_available(itf):
            return f"command interface '{itf}' is not available (hardware '{owner}' is {rm.owner_state(itf).label})"
        holder = claimed_after.get(itf)
        if holder is not None and holder != spec.name:
            return f"command interface '{itf}' is already claimed by controller '{holder}'"
    for itf in spec.state_names:
        if itf not in rm.state_interfaces:
            return f"state interface '{itf}' does not exist"
        owner = rm.interface_owner.get(itf)
        if owner not in cm.controllers and not rm.state_available(itf):
            return f"state interface '{itf}' is not available"
    return ""


def deactivate(cm: ControllerManager, spec: ControllerSpec) -> None:
    """Loop thread: active -> inactive, claims released, chained mode updated."""
    spec.stop()
    try:
        spec.c.on_deactivate(State.ACTIVE)
    except Exception as error:  # noqa: BLE001 - deactivation proceeds anyway
        cm.logger.error(f"controller '{spec.name}': on_deactivate raised {error!r}")
    _release(cm, spec)


def _release(cm: ControllerManager, spec: ControllerSpec) -> None:
    """Give back the loaned interfaces; a chained controller nobody feeds leaves chained mode."""
    for itf in spec.claimed:
        cm.rm.release(itf, spec.name)
        owner = cm.controllers.get(cm.rm.interface_owner.get(itf, ""))
        if owner is not None and not any(cm.rm.claimed.get(i) for i in list(cm.rm.command_interfaces)
                                         if cm.rm.interface_owner.get(i) == owner.name):
            owner.c.set_chained_mode(False)
    spec.claimed = []
    spec.c.command_interfaces, spec.c.state_interfaces = [], []
    spec.state = State.INACTIVE


def activate(cm: ControllerManager, spec: ControllerSpec) -> bool:
    """Loop thread: inactive -> active with its interfaces loaned. False (and rolled back) on failure."""
    rm = cm.rm
    spec.claimed = []
    try:
        for itf in spec.command_names:
            rm.claim(itf, spec.name)
            spec.claimed.append(itf)
        spec.c.command_interfaces = [rm.command_interfaces[i] for i in spec.command_names]
        spec.c.state_interfaces = [rm.state_interfaces[i] for i in spec.state_names]
    except (ResourceError, KeyError) as error:
        cm.logger.error(f"controller '{spec.name}': cannot take its interfaces: {error}")
        _release(cm, spec)
        return False
    for itf in spec.command_names:
        owner = cm.controllers.get(rm.interface_owner.get(itf, ""))
        if owner is not None:
            owner.c.set_chained_mode(True)
    try:
        result = spec.c.on_activate(State.INACTIVE)
    except Exception as error:  # noqa: BLE001
        cm.logger.error(f"controller '{spec.name}': on_activate raised {error!r}")
        result = CallbackReturn.ERROR
    if result != CallbackReturn.SUCCESS:
        cm.logger.error(f"controller '{spec.name}': on_activate failed; stays inactive")
        _release(cm, spec)
        return False
    spec.state = State.ACTIVE
    spec.start(spec.c.is_async, cm.now)
    return True


def apply_deactivations(cm: ControllerManager, plan: SwitchPlan) -> None:
    for spec in plan.deactivate:
        if spec.state == State.ACTIVE:
            deactivate(cm, spec)


def perform_command_mode_switch(cm: ControllerManager, plan: SwitchPlan) -> None:
    """After the deactivations: the hardware switches its command modes for the plan."""
    if plan.start_interfaces or plan.stop_interfaces:
        for comp in cm.rm.components.values():
            mine = set(comp.plugin.command_handles)
            start = [i for i in plan.start_interfaces if i in mine]
            stop = [i for i in plan.stop_interfaces if i in mine]
            if start or stop:
                comp.plugin.perform_command_mode_switch(start, stop)


def apply_activations(cm: ControllerManager, plan: SwitchPlan) -> None:
    for spec in plan.activate:
        if spec.state == State.INACTIVE:
            activate(cm, spec)
