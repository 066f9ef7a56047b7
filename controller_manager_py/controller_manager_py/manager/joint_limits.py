"""Joint limits: saturate commands to position, velocity and acceleration limits, counted.

One saturation rule, used on every command path:
  - by controllers (trajectory, policy, ...) through `JointLimiter`, on arrays of commands
    in the controller's joint order;
  - by the manager just before each hardware write() through `HandleLimiter`, on the
    command handles of one component (the last line of defence: ros2_control's limits stage).

The rule for a position command p* with the previous command p0 (the measured position
the first time), the previous commanded velocity v0 and the period dt (s):
    p  = clamp(p*, min_position, max_position)
    v  = clamp((p - p0) / dt, -max_velocity, max_velocity)
    v  = clamp(v, v0 - max_acceleration dt, v0 + max_acceleration dt)   (when given)
    p  = clamp(p0 + v dt, min_position, max_position)
A velocity command is clamped to +-max_velocity and its change to max_acceleration * dt.
NaN means "no command yet" and passes through untouched; an infinite command is refused
(the previous command is held). Every command that had to change is counted (`clamped`,
per joint in `clamped_by_joint`) and logged at most once per joint every 5 s with the
count so far.

Limits come from the URDF (`<limit lower upper velocity>`), narrowed by the ros2_control
`<command_interface>` min/max params; acceleration from an `acceleration` command
interface's max param, as in ros2_control. `limits_from_description(urdf)` gives them to
a controller that holds the robot description.

Example (a controller, in on_activate and update):
    self.limiter = JointLimiter(self.joints, limits_from_description(urdf), self.get_logger(), self.name)
    self.limiter.reset(measured_positions)
    for handle, value in zip(self.command_interfaces, self.limiter.limit_positions(desired, period)):
        handle.value = value
"""
from __future__ import annotations

import math
from typing import Dict, List, Mapping, Optional, Sequence

from ..hardware_interface.handle import CommandInterface, StateInterface
from ..hardware_interface.types import JointLimits
from .throttle import Throttle

_INF = float("inf")
LOG_INTERVAL_S = 5.0


def limits_from_description(urdf: str) -> Dict[str, JointLimits]:
    """Per-joint limits of every joint in the `<ros2_control>` blocks of `urdf`
    (raises hardware_interface.DescriptionError with one line when it cannot be read)."""
    from ..hardware_interface.urdf import parse_control_resources

    limits: Dict[str, JointLimits] = {}
    for info in parse_control_resources(urdf, require_limits=False):
        limits.update(info.limits)
    return limits


class _Joint:
    """One joint's limits and the state the rate limits need (previous command, velocity)."""

    __slots__ = ("name", "lo", "hi", "vmax", "amax", "previous", "velocity", "clamped")

    def __init__(self, name: str, limits: JointLimits):
        self.name = name
        self.lo, self.hi = limits.min_position, limits.max_position
        self.vmax, self.amax = limits.max_velocity, limits.max_acceleration
        self.previous = math.nan  # last limited command (NaN: start from the measured state)
        self.velocity = 0.0  # last commanded velocity (rad/s or m/s)
        self.clamped = 0

    def position(self, desired: float, previous: float, dt: float) -> float:
        """The saturation rule for a position command (see the module docstring)."""
        if desired == _INF or desired == -_INF:
            desired = previous
        p = self.hi if desired > self.hi else (self.lo if desired < self.lo else desired)
        if previous == previous and dt > 0.0:
            v_wanted = (p - previous) / dt
            vmax = self.vmax
            v = vmax if v_wanted > vmax else (-vmax if v_wanted < -vmax else v_wanted)
            if self.amax < _INF:
                dv = self.amax * dt
                v0 = self.velocity
                v = v0 + dv if v > v0 + dv else (v0 - dv if v < v0 - dv else v)
            if v != v_wanted:  # only a saturated step is rebuilt: previous + v dt != p in floats
                p = previous + v * dt
                p = self.hi if p > self.hi else (self.lo if p < self.lo else p)
            self.velocity = (p - previous) / dt
        self.previous = p
        return p

    def velocity_command(self, desired: float, dt: float) -> float:
        """The saturation rule for a velocity command."""
        v = self.velocity if desired == _INF or desired == -_INF else desired
        vmax = self.vmax
        v = vmax if v > vmax else (-vmax if v < -vmax else v)
        if self.amax < _INF and dt > 0.0:
            dv = self.amax * dt
            v0 = self.velocity
            v = v0 + dv if v > v0 + dv else (v0 - dv if v < v0 - dv else v)
        self.velocity = v
        return v


class _Counter:
    """Counts and logs (throttled per joint) the commands that had to change."""

    def __init__(self, logger, owner: str):
        self.owner = owner
        self.throttle = Throttle(logger, LOG_INTERVAL_S) if logger is not None else None
        self.clamped = 0

    def count(self, joint: _Joint, interface: str, desired: float, limited: float) -> None:
        joint.clamped += 1
        self.clamped += 1
        if self.throttle is not None and self.throttle.due(joint.name):
            self.throttle.logger.warning(
                f"{self.owner}: {joint.name} {interface} command {desired:.6g} limited to {limited:.6g} "
                f"(limits: position [{joint.lo:.6g}, {joint.hi:.6g}], velocity {joint.vmax:.6g}, "
                f"acceleration {joint.amax:.6g}); {joint.clamped} limited so far{self.throttle.suffix(joint.name)}")


class JointLimiter:
    """Saturates commands for `joints` (in this order) to `limits`; for controllers.

    joints: joint names; limits: {joint: JointLimits} (a joint missing there is not limited);
    logger/owner: where and under whose name clamps are logged (None: not logged).
    Not thread-safe: call it from one thread (the controller's update()).
    """

    def __init__(self, joints: Sequence[str], limits: Mapping[str, JointLimits], logger=None, owner: str = ""):
        self.joints = list(joints)
        self._joints = [_Joint(j, limits.get(j, JointLimits())) for j in self.joints]
        self._counter = _Counter(logger, owner or "joint limits")
        self.last_limited: List[bool] = [False] * len(self.joints)

    @property
    def clamped(self) -> int:
        """Commands changed by the limits so far (one per joint and call)."""
        return self._counter.clamped

    @property
    def clamped_by_joint(self) -> Dict[str, int]:
        return {j.name: j.clamped for j in self._joints}

    @property
    def previous_positions(self) -> List[float]:
        """The last position each joint was limited to (or reset to; NaN: none yet)."""
        return [j.previous for j in self._joints]

    def reset(self, positions: Optional[Sequence[float]] = None,
              velocities: Optional[Sequence[float]] = None) -> None:
        """Start over from measured `positions` (None: the next command is only clamped
        to the position range) and `velocities` (None: at rest). Call on activation."""
        for i, j in enumerate(self._joints):
            j.previous = float(positions[i]) if positions is not None else math.nan
            j.velocity = float(velocities[i]) if velocities is not None else 0.0

    def limit_positions(self, desired: Sequence[float], period: float) -> List[float]:
        """Position commands `desired` (one per joint) saturated for a step of `period` s."""
        out = []
        limited = self.last_limited
        for i, (j, value) in enumerate(zip(self._joints, desired)):
            if value != value:  # NaN: no command for this joint
                out.append(value)
                limited[i] = False
                continue
            result = j.position(value, j.previous, period)
            limited[i] = result != value
            if limited[i]:
                self._counter.count(j, "position", value, result)
            out.append(result)
        return out

    def limit_velocities(self, desired: Sequence[float], period: float) -> List[float]:
        """Velocity commands `desired` (one per joint) saturated for a step of `period` s."""
        out = []
        limited = self.last_limited
        for i, (j, value) in enumerate(zip(self._joints, desired)):
            if value != value:
                out.append(value)
                limited[i] = False
                continue
            result = j.velocity_command(value, period)
            limited[i] = result != value
            if limited[i]:
                self._counter.count(j, "velocity", value, result)
            out.append(result)
        return out


class HandleLimiter:
    """The manager's limits stage for one hardware component: saturates its command
    handles in place before write() and sets `handle.is_limited` when it had to."""

    def __init__(self, limits: Mapping[str, JointLimits], commands: Mapping[str, CommandInterface],
                 states: Mapping[str, StateInterface], logger=None, owner: str = ""):
        self._counter = _Counter(logger, f"hardware '{owner}'" if owner else "joint limits")
        self._positions: List[tuple] = []  # (joint, command handle, measured position handle or None)
        self._velocities: List[tuple] = []  # (joint, command handle)
        for joint, lim in limits.items():
            pos = commands.get(f"{joint}/position")
            if pos is not None and (lim.has_position_limits or lim.has_velocity_limits
                                    or lim.has_acceleration_limits) and lim.enforced("position"):
                self._positions.append((_Joint(joint, lim), pos, states.get(f"{joint}/position")))
            vel = commands.get(f"{joint}/velocity")
            if vel is not None and (lim.has_velocity_limits or lim.has_acceleration_limits) \
                    and lim.enforced("velocity"):
                self._velocities.append((_Joint(joint, lim), vel))

    @property
    def clamped(self) -> int:
        """Commands changed by the limits since start."""
        return self._counter.clamped

    def limited_names(self) -> List[str]:
        """The command interfaces this stage may change."""
        return [h.name for _, h, _ in self._positions] + [h.name for _, h in self._velocities]

    def reset(self) -> None:
        """Forget the previous commands (on activation: start from the measured state)."""
        for joint, _, _ in self._positions:
            joint.previous, joint.velocity = math.nan, 0.0
        for joint, _ in self._velocities:
            joint.velocity = 0.0

    def enforce(self, period: float) -> None:
        for joint, handle, state in self._positions:
            value = handle.value
            if value != value:  # NaN: no command yet
                handle.is_limited = False
                continue
            previous = joint.previous
            if previous != previous and state is not None:
                previous = state.value
            limited = joint.position(value, previous, period)
            handle.is_limited = limited != value
            if handle.is_limited:
                handle.value = limited
                self._counter.count(joint, "position", value, limited)
        for joint, handle in self._velocities:
            value = handle.value
            if value != value:
                handle.is_limited = False
                continue
            limited = joint.velocity_command(value, period)
            handle.is_limited = limited != value
            if handle.is_limited:
                handle.value = limited
                self._counter.count(joint, "velocity", value, limited)
