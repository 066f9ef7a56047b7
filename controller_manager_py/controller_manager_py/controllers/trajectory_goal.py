"""A trajectory as the trajectory controller's loop sees it, and the check at its edge.

`check_trajectory` turns a trajectory_msgs/JointTrajectory into a `Goal` in the controller's
joint order, or raises `TrajectoryError` with one line saying why; `GoalRun` is an action
goal's state shared by the loop (which finishes it) and the action server (which reports it).
Plain Python: the controller (joint_trajectory.py) and its action server
(follow_joint_trajectory.py) both build on this module, neither on the other's.
"""
from __future__ import annotations

import math
from typing import List, Optional, Tuple

from . import tolerances as tol


class TrajectoryError(ValueError):
    """A trajectory the controller refuses (the message says why)."""


class Goal:
    """A checked trajectory in controller joint order: times (s), positions[point][joint],
    velocities (same shape, or None), stamp (s, 0 = start when picked up), mask (joints it
    commands), run (the action goal following it, or None for a topic trajectory), decelerate
    (an empty one: brake to a stop if configured, else hold)."""

    __slots__ = ("times", "positions", "velocities", "stamp", "mask", "run", "decelerate")

    def __init__(self, times, positions, velocities, stamp, mask, run=None, decelerate=False):
        self.times, self.positions, self.velocities, self.stamp, self.mask = times, positions, velocities, stamp, mask
        self.run, self.decelerate = run, decelerate


class GoalRun:
    """One action goal as the loop sees it. The loop writes `outcome` once
    ((status, error_code, error_string), status in SUCCEEDED, ABORTED, CANCELED); the
    action server (executor) reads it, reports the result and drops the run."""

    SUCCEEDED, ABORTED, CANCELED = "succeeded", "aborted", "canceled"
    __slots__ = ("tolerances", "outcome", "handle")

    def __init__(self, tolerances: tol.Tolerances, handle=None):
        self.tolerances, self.handle = tolerances, handle
        self.outcome: Optional[Tuple[str, int, str]] = None

    def finish(self, status: str, code: int, text: str) -> None:
        if self.outcome is None:
            self.outcome = (status, code, text)


# FollowJointTrajectory.Result error codes (control_msgs), without importing ROS here
SUCCESSFUL, INVALID_GOAL, PATH_TOLERANCE_VIOLATED, GOAL_TOLERANCE_VIOLATED = 0, -1, -4, -5


def check_trajectory(msg, joints: List[str], allow_partial: bool) -> Goal:
    """Validate and reorder a JointTrajectory; raises TrajectoryError with one clear line."""
    names = list(msg.joint_names)
    unknown = [n for n in names if n not in joints]
    if unknown:
        raise TrajectoryError(f"unknown joint(s) {unknown} (controller joints: {joints})")
    if len(set(names)) != len(names):
        raise TrajectoryError(f"duplicate joint names {names}")
    if not names and msg.points:
        raise TrajectoryError("no joint_names")
    if len(names) != len(joints) and not allow_partial and msg.points:
        raise TrajectoryError(f"trajectory names {len(names)} of {len(joints)} joints and "
                              "allow_partial_joints_goal is false")
    index = [names.index(j) if j in names else -1 for j in joints]
    times, positions, velocities = [], [], []
    has_velocities = bool(msg.points) and all(len(p.velocities) for p in msg.points)
    previous = -1.0
    for k, point in enumerate(msg.points):
        t = point.time_from_start.sec + point.time_from_start.nanosec * 1e-9
        if t <= previous or t < 0.0:
            raise TrajectoryError(f"point {k}: time_from_start {t:.6f} s is not after the previous one "
                                  f"({previous:.6f} s); times must increase strictly")
        previous = t
        if len(point.positions) != len(names):
            raise TrajectoryError(f"point {k}: {len(point.positions)} positions for {len(names)} joints")
        if point.velocities and len(point.velocities) != len(names):
            raise TrajectoryError(f"point {k}: {len(point.velocities)} velocities for {len(names)} joints")
        values = list(point.positions) + list(point.velocities)
        if not all(math.isfinite(v) for v in values):
            raise TrajectoryError(f"point {k}: non-finite value")
        times.append(t)
        positions.append([point.positions[i] if i >= 0 else math.nan for i in index])
        if has_velocities:
            velocities.append([point.velocities[i] if i >= 0 else 0.0 for i in index])
    stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
    return Goal(times, positions, velocities if has_velocities else None, stamp, [i >= 0 for i in index])
