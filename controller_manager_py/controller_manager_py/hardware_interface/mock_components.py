"""mock_components/GenericSystem: commands mirrored to states, for tests and dry runs.

Hardware parameters (as ros2_control's GenericSystem):
  position_state_following_offset (float, default 0): added to the mirrored position state;
  custom_interface_with_following_offset (str): put the offset position there instead;
  calculate_dynamics (bool): derive velocity/acceleration states from successive positions;
  disable_commands (bool): ignore commands (states stay at their initial values).
A command interface with no command yet (NaN) leaves its state unchanged. A gpio or
sensor state interface with a matching command interface name mirrors it as well.
"""
from __future__ import annotations

import math
from typing import List, Tuple

from .component import SystemInterface
from .handle import Handle
from .types import CallbackReturn, HardwareInfo, return_type


class GenericSystem(SystemInterface):
    def on_init(self, info: HardwareInfo) -> CallbackReturn:
        result = super().on_init(info)
        if result != CallbackReturn.SUCCESS:
            return result
        params = info.hardware_parameters
        try:
            self.offset = float(params.get("position_state_following_offset", "0"))
        except ValueError:
            self.get_logger().error(f"{info.name}: position_state_following_offset must be a number")
            return CallbackReturn.ERROR
        custom = params.get("custom_interface_with_following_offset", "")
        self.calculate_dynamics = params.get("calculate_dynamics", "false").lower() == "true"
        self.disable_commands = params.get("disable_commands", "false").lower() == "true"
        for handle in self.state_handles.values():  # states start at 0 unless initial_value
            if math.isnan(handle.value):
                handle.value = 0.0
        # (command, state, offset) pairs, resolved once so read() is a flat loop
        self._mirror: List[Tuple[Handle, Handle, float]] = []
        self._dynamics: List[Tuple[Handle, Handle]] = []  # (position state, velocity state)
        for command in self.command_handles.values():
            prefix, itf = command.prefix_name, command.interface_name
            target, offset = itf, 0.0
            if itf == "position" and self.offset:
                target, offset = (custom or "position"), self.offset
            state = self.state_handles.get(f"{prefix}/{target}")
            if state is not None:
                self._mirror.append((command, state, offset))
        for state in self.state_handles.values():
            if state.interface_name == "position":
                velocity = self.state_handles.get(f"{state.prefix_name}/velocity")
                if velocity is not None and f"{state.prefix_name}/velocity" not in self.command_handles:
                    self._dynamics.append((state, velocity))
        self._last_positions = [p.value for p, _ in self._dynamics]
        return CallbackReturn.SUCCESS

    def read(self, time: float, period: float) -> return_type:
        if self.disable_commands:
            return return_type.OK
        for command, state, offset in self._mirror:
            value = command.value
            if value == value:  # not NaN: a command has been written
                state.value = value + offset
        if self.calculate_dynamics and period > 0.0:
            last = self._last_positions
            for i, (position, velocity) in enumerate(self._dynamics):
                velocity.value = (position.value - last[i]) / period
                last[i] = position.value
        return return_type.OK
