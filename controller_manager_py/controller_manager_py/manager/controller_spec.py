"""A loaded controller and the manager's bookkeeping around it (rate divisor, stats, async)."""
from __future__ import annotations

import time as _time
from typing import List, Optional

from ..controller_interface.base import ControllerInterface, interface_configuration_type
from ..hardware_interface.types import State, return_type
from .async_handler import AsyncHandler
from .statistics import PeriodicityStats


class ControllerSpec:
    def __init__(self, name: str, type_name: str, controller: ControllerInterface,
                 fallback_controllers: List[str], param_values: Optional[dict]):
        self.name, self.type, self.c = name, type_name, controller
        self.fallback_controllers = list(fallback_controllers)
        self.param_values = param_values  # dict for pure use, None = the node's parameters
        self.divisor = 1
        self.stats = PeriodicityStats()
        self.async_handler: Optional[AsyncHandler] = None
        self.claimed: List[str] = []
        self.command_names: List[str] = []
        self.state_names: List[str] = []
        self.update_errors = 0
        self._last_time = float("nan")

    @property
    def state(self) -> State:
        return self.c.lifecycle_state

    @state.setter
    def state(self, value: State) -> None:
        self.c.lifecycle_state = value

    def resolve_interfaces(self, available_commands, available_states) -> None:
        """Fill command_names/state_names from the controller's configuration (ALL expands)."""
        cmd, st = self.c.command_interface_configuration(), self.c.state_interface_configuration()
        self.command_names = (list(available_commands) if cmd.type == interface_configuration_type.ALL
                              else list(cmd.names) if cmd.type == interface_configuration_type.INDIVIDUAL else [])
        self.state_names = (list(available_states) if st.type == interface_configuration_type.ALL
                            else list(st.names) if st.type == interface_configuration_type.INDIVIDUAL else [])

    def set_rate(self, manager_rate: int, logger) -> None:
        rate = self.c.update_rate or manager_rate
        if rate > manager_rate:
            logger.warning(f"controller '{self.name}': update_rate {rate} Hz is above the manager's "
                           f"{manager_rate} Hz; running at {manager_rate} Hz")
            rate = manager_rate
        self.divisor = max(1, round(manager_rate / rate))
        if manager_rate % rate:
            logger.warning(f"controller '{self.name}': update_rate {rate} Hz is not a divisor of "
                           f"{manager_rate} Hz; running at {manager_rate / self.divisor:g} Hz")

    @property
    def effective_rate(self) -> int:
        return int(round(self.c.manager_update_rate / self.divisor)) if self.c.manager_update_rate else 0

    def timed_update(self, time: float, period: float) -> return_type:
        """Call update() and record execution time and periodicity (loop or async worker)."""
        start = _time.monotonic()
        result = self.c.update(time, period)
        self.stats.add(start, _time.monotonic())
        return result

    def run(self, time: float, nominal_period: float) -> return_type:
        """One due update from the loop (synchronously, or a trigger of the async worker)."""
        last = self._last_time
        period = time - last if last == last else nominal_period
        self._last_time = time
        handler = self.async_handler
        if handler is not None:
            return handler.trigger(time, period)
        return self.timed_update(time, period)

    def start(self, is_async: bool, clock) -> None:
        self._last_time = float("nan")
        if is_async and self.async_handler is None:
            self.async_handler = AsyncHandler(self.name, self.timed_update, clock=clock)

    def stop(self) -> None:
        if self.async_handler is not None:
            self.async_handler.wait_idle()
            self.async_handler.stop()
            self.async_handler = None
