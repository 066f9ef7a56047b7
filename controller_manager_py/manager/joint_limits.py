"""Joint limits as the last line of defence, applied to commands just before write().

Position commands are clamped to [min_position, max_position] and their change per write
to max_velocity * period (relative to the previous limited command, or the measured
position the first time). Velocity commands are clamped to +-max_velocity. A command that
had to change sets `handle.is_limited` (shown in introspection as
`command_interface.<name>.is_limited`). NaN means "no command yet" and passes through;
an infinite command is replaced by the previous one.
"""
from __future__ import annotations

from typing import Dict, List, Optional

from ..hardware_interface.handle import CommandInterface, StateInterface
from ..hardware_interface.types import JointLimits


class _PositionLimit:
    __slots__ = ("command", "state", "lo", "hi", "vmax", "previous")

    def __init__(self, command: CommandInterface, state: Optional[StateInterface], limits: JointLimits):
        self.command, self.state = command, state
        self.lo, self.hi, self.vmax = limits.min_position, limits.max_position, limits.max_velocity
        self.previous = float("nan")


class JointLimiter:
    """Enforces one hardware component's limits on its command handles."""

    def __init__(self, limits: Dict[str, JointLimits], commands: Dict[str, CommandInterface],
                 states: Dict[str, StateInterface]):
        self._positions: List[_PositionLimit] = []
        self._velocities: List[tuple] = []
        for joint, lim in limits.items():
            pos = commands.get(f"{joint}/position")
            if pos is not None and (lim.has_position_limits or lim.has_velocity_limits) and lim.enforced("position"):
                self._positions.append(_PositionLimit(pos, states.get(f"{joint}/position"), lim))
            vel = commands.get(f"{joint}/velocity")
            if vel is not None and lim.has_velocity_limits and lim.enforced("velocity"):
                self._velocities.append((vel, lim.max_velocity))

    def limited_names(self) -> List[str]:
        """The command interfaces this limiter may change."""
        return [p.command.name for p in self._positions] + [h.name for h, _ in self._velocities]

    def reset(self) -> None:
        """Forget the previous commands (on activation: start from the measured state)."""
        for p in self._positions:
            p.previous = float("nan")

    def enforce(self, period: float) -> None:
        for p in self._positions:
            handle = p.command
            value = handle.value
            if value != value:  # NaN: no command yet
                handle.is_limited = False
                continue
            limited = value
            previous = p.previous
            if previous != previous and p.state is not None:
                previous = p.state.value
            if limited in (float("inf"), float("-inf")):
                limited = previous
            if limited < p.lo:
                limited = p.lo
            elif limited > p.hi:
                limited = p.hi
            if previous == previous and period > 0.0 and p.vmax < float("inf"):
                step = p.vmax * period
                if limited > previous + step:
                    limited = previous + step
                elif limited < previous - step:
                    limited = previous - step
            handle.is_limited = limited != value
            handle.value = limited
            p.previous = limited
        for handle, vmax in self._velocities:
            value = handle.value
            if value != value:
                continue
            limited = vmax if value > vmax else (-vmax if value < -vmax else value)
            handle.is_limited = limited != value
            handle.value = limited
