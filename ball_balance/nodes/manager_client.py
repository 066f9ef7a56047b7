"""Awaitable calls to a controller manager's services, each with a deadline, for a node that
runs on one single-threaded executor (the robot manager).

Every call is made from a coroutine the executor runs (an async service callback or a task
from `executor.create_task`) and awaited: nothing here blocks a callback. A call that gets no
answer before its deadline raises ManagerCallError naming the service; its pending request is
dropped (`Client.remove_pending_request`), so a late answer changes nothing.
"""
from __future__ import annotations

from typing import Iterable, List

from builtin_interfaces.msg import Duration
from controller_manager_msgs import srv
from lifecycle_msgs.msg import State as StateMsg
from rclpy.clock import Clock, ClockType
from rclpy.task import Future

STRICT, BEST_EFFORT = srv.SwitchController.Request.STRICT, srv.SwitchController.Request.BEST_EFFORT
SERVICES = {
    "list_controllers": srv.ListControllers,
    "list_hardware_components": srv.ListHardwareComponents,
    "set_hardware_component_state": srv.SetHardwareComponentState,
    "switch_controller": srv.SwitchController,
    "configure_controller": srv.ConfigureController,
}


class ManagerCallError(RuntimeError):
    """A controller manager service was not there, did not answer in time, or refused."""


async def sleep(node, seconds: float, group=None) -> None:
    """Wait `seconds` of steady time inside a coroutine, without blocking the executor. The
    awaiting callback's group must let this timer run meanwhile (a reentrant group)."""
    done = Future()
    timer = node.create_timer(seconds, lambda: done.done() or done.set_result(True), group,
                              clock=Clock(clock_type=ClockType.STEADY_TIME))
    try:
        await done
    finally:
        node.destroy_timer(timer)


class ManagerClient:
    def __init__(self, node, manager: str, timeout_s: float, group=None):
        """manager: the controller manager's node name (e.g. /controller_manager); group: the
        callback group of the clients and deadline timers (reentrant, as the awaiting callers')."""
        self.node, self.manager, self.timeout_s, self.group = node, manager.rstrip("/"), timeout_s, group
        self.clients = {name: node.create_client(t, f"{self.manager}/{name}", callback_group=group)
                        for name, t in SERVICES.items()}

    def ready(self) -> bool:
        return all(c.service_is_ready() for c in self.clients.values())

    async def call(self, name: str, request, timeout_s: float = 0.0):
        """The response of `name` (one of SERVICES) to `request`, or ManagerCallError."""
        client = self.clients[name]
        timeout_s = timeout_s or self.timeout_s
        service = f"{self.manager}/{name}"
        if not client.service_is_ready():
            raise ManagerCallError(f"{service} is not available")
        future = client.call_async(request)
        done = Future()
        future.add_done_callback(lambda f: done.done() or done.set_result(True))
        timer = self.node.create_timer(timeout_s, lambda: done.done() or done.set_result(False), self.group,
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))
        try:
            answered = await done
        finally:
            self.node.destroy_timer(timer)
        if not answered:
            client.remove_pending_request(future)
            raise ManagerCallError(f"{service} did not answer within {timeout_s:g} s")
        if future.exception() is not None:
            raise ManagerCallError(f"{service} failed: {future.exception()}")
        return future.result()

    async def controllers(self) -> dict:
        """name -> ControllerState."""
        response = await self.call("list_controllers", srv.ListControllers.Request())
        return {c.name: c for c in response.controller}

    async def hardware(self) -> dict:
        """name -> lifecycle label of each hardware component."""
        response = await self.call("list_hardware_components", srv.ListHardwareComponents.Request())
        return {c.name: c.state.label for c in response.component}

    async def set_hardware_state(self, name: str, state_id: int, label: str) -> None:
        request = srv.SetHardwareComponentState.Request(name=name, target_state=StateMsg(id=state_id, label=label))
        response = await self.call("set_hardware_component_state", request)
        if not response.ok:
            raise ManagerCallError(f"hardware '{name}' did not become {label} (it is {response.state.label or '?'}; "
                                   f"see the controller manager's log)")

    async def switch(self, activate: Iterable[str] = (), deactivate: Iterable[str] = (),
                     strictness: int = STRICT) -> None:
        seconds = self.timeout_s
        request = srv.SwitchController.Request(
            activate_controllers=list(activate), deactivate_controllers=list(deactivate), strictness=strictness,
            activate_asap=True, timeout=Duration(sec=int(seconds), nanosec=int(seconds % 1 * 1e9)))
        response = await self.call("switch_controller", request)
        if not response.ok:
            what = ", ".join(f"{verb} {names}" for verb, names in (("activate", request.activate_controllers),
                                                                    ("deactivate", request.deactivate_controllers))
                             if names)
            raise ManagerCallError(f"switch_controller ({what}) refused: {response.message or 'see its log'}")

    async def configure_controller(self, name: str) -> None:
        response = await self.call("configure_controller", srv.ConfigureController.Request(name=name))
        if not response.ok:
            raise ManagerCallError(f"controller '{name}' did not configure (see the controller manager's log)")


def names(items: Iterable[str]) -> List[str]:
    """A string-array parameter without its empty placeholder entries."""
    return [n for n in items if n]
