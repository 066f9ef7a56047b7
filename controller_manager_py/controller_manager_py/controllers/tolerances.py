"""Trajectory tolerances and the limits a trajectory must respect (pure Python, no ROS).

Tolerances (joint_trajectory_controller's semantics, Jazzy):
  - per joint, a path tolerance (checked while the trajectory runs) and a goal tolerance
    (checked after its last point) on position, velocity and acceleration errors, where
    error = desired - measured; a tolerance of 0 is not checked;
  - controller defaults come from the parameters `constraints.<joint>.trajectory` (path
    position), `constraints.<joint>.goal` (goal position),
    `constraints.stopped_velocity_tolerance` (goal velocity, every joint) and
    `constraints.goal_time` (s after the last point's time by which the goal tolerance must
    hold; 0 = wait as long as it takes);
  - a FollowJointTrajectory goal overrides them per joint and field: 0 keeps the default,
    -1 erases it (not checked), any other negative value is illegal. An illegal value or an
    unknown joint name makes the whole goal use the defaults (one error line), as upstream.

Limits: a trajectory is refused when a waypoint lies outside a joint's position limits or
gives a waypoint velocity above its velocity limit, so the controller never sets out for a
point the joint cannot reach. (A path that is merely too fast is followed as fast as the
limits allow: the controller passes its desired state through the shared JointLimiter.)
The limits are the robot description's, as the manager's limits stage enforces them; a
joint whose limits are disabled there (`<limits enable="false"/>`) is not checked here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

from ..hardware_interface.types import JointLimits
from ..parameters import Param

ERASE = -1.0
"""A goal tolerance of -1: this tolerance is not checked for this goal."""


@dataclass
class StateTolerance:
    """Allowed |error| of one joint; 0 = not checked."""

    position: float = 0.0
    velocity: float = 0.0
    acceleration: float = 0.0


@dataclass
class Tolerances:
    """Path and goal tolerances of every controller joint (controller order), goal time (s)."""

    path: List[StateTolerance] = field(default_factory=list)
    goal: List[StateTolerance] = field(default_factory=list)
    goal_time: float = 0.0


def constraint_params(joints: Sequence[str]) -> List[Param]:
    """The `constraints.*` parameters of a trajectory controller with these joints."""
    params = [
        Param("constraints.stopped_velocity_tolerance", 0.01,
              "goal velocity tolerance of every joint: the arm counts as stopped below it", unit="rad/s", min=0.0,
              user_facing=True),
        Param("constraints.goal_time", 0.0,
              "time after the last point by which the goal tolerance must hold (0 = no limit)", unit="s", min=0.0,
              user_facing=True),
        Param("constraints.decelerate_on_cancel", False,
              "on a cancel or an abort, decelerate to a stop at each joint's max_deceleration_on_cancel "
              "instead of holding where the arm is (needs every joint's, and velocity states)", read_only=True),
    ]
    for joint in joints:
        params.append(Param(f"constraints.{joint}.trajectory", 0.0,
                            f"path position tolerance of {joint} (0 = not checked)", unit="rad", min=0.0,
                            user_facing=True))
        params.append(Param(f"constraints.{joint}.goal", 0.0,
                            f"goal position tolerance of {joint} (0 = not checked)", unit="rad", min=0.0,
                            user_facing=True))
        params.append(Param(f"constraints.{joint}.max_deceleration_on_cancel", 0.0,
                            f"deceleration of {joint} when stopping with decelerate_on_cancel (0 = not set)",
                            unit="rad/s^2", min=0.0, read_only=True))
    return params


def stopping_profile(positions: Sequence[float], velocities: Sequence[float], decelerations: Sequence[float]):
    """Each joint brakes from (p, v) at its constant deceleration a to p + sign(v) v^2 / (2 a) in
    |v| / a (ros2_controllers' decelerate_to_hold_position). Returns (times, knot positions,
    knot velocities) with knots at 0, every joint's stop time and the last one: between two
    knots each joint's motion is one parabola, which a cubic Hermite segment through the knots'
    positions and velocities reproduces exactly. A single knot when nothing moves."""
    stop_times = [abs(v) / a for v, a in zip(velocities, decelerations)]
    times = sorted({0.0, *(t for t in stop_times if t > 1e-9)})
    knots_p, knots_v = [], []
    for p, v, a, t_stop in zip(positions, velocities, decelerations, stop_times):
        brake = -a if v > 0.0 else a
        knots_p.append([p + v * min(t, t_stop) + 0.5 * brake * min(t, t_stop) ** 2 for t in times])
        knots_v.append([v + brake * t if t < t_stop else 0.0 for t in times])
    return times, knots_p, knots_v


def default_tolerances(joints: Sequence[str], params: Mapping) -> Tolerances:
    """Tolerances from the `constraints.*` parameter values."""
    stopped = params["constraints.stopped_velocity_tolerance"]
    return Tolerances(
        path=[StateTolerance(position=params[f"constraints.{j}.trajectory"]) for j in joints],
        goal=[StateTolerance(position=params[f"constraints.{j}.goal"], velocity=stopped) for j in joints],
        goal_time=params["constraints.goal_time"])


def resolve(default: float, given: float) -> float:
    """A goal's tolerance value against the default: > 0 replaces it, 0 keeps it, -1 erases it."""
    if given > 0.0:
        return given
    if abs(given - ERASE) < 1e-6:
        return 0.0
    if given < 0.0 or not math.isfinite(given):
        raise ValueError(f"{given} (use > 0, 0 for the default or -1 to erase)")
    return default


def goal_tolerances(defaults: Tolerances, joints: Sequence[str], path_tolerance, goal_tolerance,
                    goal_time_tolerance_s: float) -> Tuple[Tolerances, Optional[str]]:
    """Tolerances for one goal (JointTolerance lists, goal_time_tolerance in s).

    Returns (tolerances, None), or (the defaults, why the goal's were not used)."""
    result = Tolerances([StateTolerance(t.position, t.velocity, t.acceleration) for t in defaults.path],
                        [StateTolerance(t.position, t.velocity, t.acceleration) for t in defaults.goal],
                        defaults.goal_time)
    try:
        result.goal_time = resolve(defaults.goal_time, goal_time_tolerance_s)
    except ValueError as error:
        return defaults, f"goal_time_tolerance {error}"
    for what, given, target in (("path_tolerance", path_tolerance, result.path),
                                ("goal_tolerance", goal_tolerance, result.goal)):
        for tolerance in given:
            if tolerance.name not in joints:
                return defaults, f"{what} names joint '{tolerance.name}', not one of {list(joints)}"
            state = target[list(joints).index(tolerance.name)]
            for variable in ("position", "velocity", "acceleration"):
                try:
                    setattr(state, variable, resolve(getattr(state, variable), getattr(tolerance, variable)))
                except ValueError as error:
                    return defaults, f"{what} of '{tolerance.name}': {variable} {error}"
    return result, None


def violation(joints: Sequence[str], tolerances: Sequence[StateTolerance], error_p: Sequence[float],
              error_v: Optional[Sequence[float]]) -> Optional[str]:
    """None when every joint is within its tolerance, else which joint, variable and by how much."""
    for j, tolerance in enumerate(tolerances):
        if tolerance.position > 0.0 and abs(error_p[j]) > tolerance.position:
            return f"{joints[j]} position error {error_p[j]:+.4f} rad exceeds {tolerance.position:.4f}"
        if error_v is not None and tolerance.velocity > 0.0 and abs(error_v[j]) > tolerance.velocity:
            return f"{joints[j]} velocity error {error_v[j]:+.4f} rad/s exceeds {tolerance.velocity:.4f}"
    return None


def check_limits(joints: Sequence[str], limits: Mapping[str, JointLimits],
                 positions: Sequence[Sequence[float]], velocities: Optional[Sequence[Sequence[float]]],
                 mask: Sequence[bool]) -> Optional[str]:
    """Why a trajectory (controller joint order) asks for what its joints cannot do, or None:
    a waypoint outside a joint's position limits, or a waypoint velocity above its velocity
    limit. `mask`: the joints the trajectory commands."""
    tol = 1e-9  # a waypoint exactly on a limit is reachable
    for j, joint in enumerate(joints):
        lim = limits.get(joint)
        if lim is None or not mask[j] or not lim.enforced("position"):
            continue
        for k, point in enumerate(positions):
            p = point[j]
            if p < lim.min_position - tol or p > lim.max_position + tol:
                return (f"point {k}: {joint} at {p:.4f} rad is outside its position limits "
                        f"[{lim.min_position:.4f}, {lim.max_position:.4f}]")
            if velocities is not None and abs(velocities[k][j]) > lim.max_velocity + tol:
                return (f"point {k}: {joint} velocity {velocities[k][j]:.4f} rad/s exceeds its limit "
                        f"{lim.max_velocity:.4f}")
    return None


def limits_of(joints: Sequence[str], limits: Optional[Mapping[str, JointLimits]]) -> Dict[str, JointLimits]:
    """The limits of `joints` that are known (joints without limits are left out)."""
    return {j: limits[j] for j in joints if limits and j in limits}
