"""joint_trajectory_controller/JointTrajectoryController (position command interface).

Topic `~/joint_trajectory` (trajectory_msgs/JointTrajectory). The subscription callback
(executor thread) checks the message at the edge: joint names known and unique (all of
`joints` unless allow_partial_joints_goal), one finite position per joint per point,
velocities empty or complete, time_from_start strictly increasing. A bad trajectory is
refused with one throttled warning and counted; the running one continues. A good one
is reordered to the controller's joint order and handed to update() through one slot.

update() (real-time) starts a new trajectory from the current desired state (position
and velocity), so there is no jump: the first segment joins that state to the first
waypoint still in the future. Waypoints with velocities use them (cubic Hermite);
position-only waypoints get velocities from the clamped cubic spline (O(n) tridiagonal
solve, rest at the end). Trajectory time runs at `period * speed_scaling` when
`speed_scaling_interface_name` names a state interface (the UR driver's
speed_scaling/speed_scaling_factor, a fraction 0..1): the scaled controller. A header
stamp of zero starts the trajectory now; otherwise at the stamp (manager clock). After
the last waypoint the controller holds it. An empty trajectory stops: hold where we are.
"""
from __future__ import annotations

import math
from typing import List, Optional, Tuple

from ..controller_interface.base import (
    ControllerInterface,
    InterfaceConfiguration,
    interface_configuration_type,
)
from ..hardware_interface.types import CallbackReturn, State, return_type
from ..manager.throttle import Throttle
from ..parameters import Param
from .forward_command import _non_empty
from .spline import clamped_spline_velocities, hermite


class TrajectoryError(ValueError):
    """A trajectory the controller refuses (the message says why)."""


class Goal:
    """A checked trajectory in controller joint order: times (s), positions[point][joint],
    velocities (same shape, or None), stamp (s, 0 = start when picked up)."""

    __slots__ = ("times", "positions", "velocities", "stamp", "mask")

    def __init__(self, times, positions, velocities, stamp, mask):
        self.times, self.positions, self.velocities, self.stamp, self.mask = times, positions, velocities, stamp, mask


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


class JointTrajectoryController(ControllerInterface):
    PARAMS = (
        Param("joints", [""], "controlled joints", check=_non_empty),
        Param("command_interfaces", ["position"], "command interfaces (position supported)",
              check=lambda v: None if list(v) == ["position"] else "only [position] is supported"),
        Param("state_interfaces", ["position", "velocity"], "state interfaces read"),
        Param("allow_partial_joints_goal", False, "accept trajectories naming only some joints"),
        Param("speed_scaling_interface_name", "", "state interface scaling trajectory time (scaled JTC)"),
    )

    def on_configure(self, previous_state: State) -> CallbackReturn:
        self.joints = [j for j in self.params["joints"] if j]
        self.state_names = list(self.params["state_interfaces"])
        if "position" not in self.state_names:
            self.get_logger().error(f"{self.name}: state_interfaces must include position")
            return CallbackReturn.ERROR
        self.scaling_name = self.params["speed_scaling_interface_name"]
        self.throttle = Throttle(self.get_logger())
        self.refused = 0
        self._slot: Optional[Goal] = None
        self._sub = None
        self.traj_time = 0.0
        self.desired_p = [math.nan] * len(self.joints)
        self.desired_v = [0.0] * len(self.joints)
        self.introspection.clear()  # (re)configure: the getters read the live attributes
        self.register_introspection("trajectory_time", lambda: self.traj_time)
        self.register_introspection("refused_trajectories", lambda: float(self.refused))
        for j, joint in enumerate(self.joints):
            self.register_introspection(f"{joint}.desired_position", lambda j=j: self.desired_p[j])
            self.register_introspection(f"{joint}.desired_velocity", lambda j=j: self.desired_v[j])
        node = self.get_node()
        if node is not None:
            from trajectory_msgs.msg import JointTrajectory
            self._sub = node.create_subscription(JointTrajectory, "~/joint_trajectory", self.on_trajectory, 10)
        return CallbackReturn.SUCCESS

    def on_cleanup(self, previous_state: State) -> CallbackReturn:
        if self._sub is not None:
            self.get_node().destroy_subscription(self._sub)
            self._sub = None
        return CallbackReturn.SUCCESS

    def command_interface_configuration(self) -> InterfaceConfiguration:
        return InterfaceConfiguration(interface_configuration_type.INDIVIDUAL, [f"{j}/position" for j in self.joints])

    def state_interface_configuration(self) -> InterfaceConfiguration:
        names = [f"{j}/{i}" for j in self.joints for i in self.state_names]
        if self.scaling_name:
            names.append(self.scaling_name)
        return InterfaceConfiguration(interface_configuration_type.INDIVIDUAL, names)

    # ---- edge: subscription callback (executor thread) ----------------------------------------
    def on_trajectory(self, msg) -> bool:
        try:
            goal = check_trajectory(msg, self.joints, self.params["allow_partial_joints_goal"])
        except TrajectoryError as error:
            self.refused += 1
            self.throttle.warn("refused", f"{self.name}: trajectory refused: {error} (refused so far: {self.refused})")
            return False
        self._slot = goal
        return True

    # ---- lifecycle in the loop ------------------------------------------------------------------
    def on_activate(self, previous_state: State) -> CallbackReturn:
        n, states = len(self.joints), self.state_interfaces
        per_joint = len(self.state_names)
        self._pos = [states[k * per_joint + self.state_names.index("position")] for k in range(n)]
        self._vel = ([states[k * per_joint + self.state_names.index("velocity")] for k in range(n)]
                     if "velocity" in self.state_names else None)
        self._scaling = states[-1] if self.scaling_name else None
        self.desired_p = [h.value for h in self._pos]  # hold where we are
        self.desired_v = [0.0] * n
        self._slot = None
        self._active: Optional[Goal] = None
        self._knots: List[Tuple[List[float], List[List[float]], List[List[float]]]] = []
        self._segment = 0
        self.traj_time = 0.0
        for handle, p in zip(self.command_interfaces, self.desired_p):
            handle.value = p
        return CallbackReturn.SUCCESS

    def on_deactivate(self, previous_state: State) -> CallbackReturn:
        self._slot = None
        self._active = None
        return CallbackReturn.SUCCESS

    # ---- real-time ------------------------------------------------------------------------------
    def _start(self, goal: Goal, time: float) -> None:
        """Build knots from the current desired state to the goal's future waypoints."""
        self._active = goal
        self.traj_time = time - goal.stamp if goal.stamp > 0.0 else 0.0
        if abs(self.traj_time) > 5.0:  # most likely wall-clock stamps against simulated time, or the reverse
            self.throttle.warn("stamp", f"{self.name}: trajectory stamped {-self.traj_time:+.1f} s from now; "
                                        "check use_sim_time (a zero stamp starts it on arrival)")
        if not goal.times:  # empty trajectory: stop here
            self._knots = []
            self.desired_v = [0.0] * len(self.joints)
            return
        first = next((k for k, t in enumerate(goal.times) if t > self.traj_time), len(goal.times))
        if first == len(goal.times):  # all in the past: go to the last point
            first = len(goal.times) - 1
            t0 = goal.times[first] - 1e-3
        else:
            t0 = self.traj_time
        times = [t0, *goal.times[first:]]
        knots_p, knots_v = [], []
        for j in range(len(self.joints)):
            p = [self.desired_p[j]] + [goal.positions[k][j] if goal.mask[j] else self.desired_p[j]
                                       for k in range(first, len(goal.times))]
            if goal.velocities is not None:
                v = [self.desired_v[j]] + [goal.velocities[k][j] for k in range(first, len(goal.times))]
            else:
                v = clamped_spline_velocities(times, p, self.desired_v[j], 0.0)
            knots_p.append(p)
            knots_v.append(v)
        self._knots = [(times, knots_p, knots_v)]
        self._segment = 0

    def update(self, time: float, period: float) -> return_type:
        goal = self._slot
        if goal is not None and goal is not self._active:
            self._start(goal, time)
        elif self._knots:
            scale = 1.0
            if self._scaling is not None:
                scale = self._scaling.value
                scale = 1.0 if scale != scale else (0.0 if scale < 0.0 else scale)
            self.traj_time += period * scale
        if not self._knots:
            return return_type.OK
        times, knots_p, knots_v = self._knots[0]
        t = self.traj_time
        if t < times[0]:
            return return_type.OK  # stamped in the future: hold
        last = len(times) - 1
        seg = self._segment
        while seg < last - 1 and t >= times[seg + 1]:
            seg += 1
        self._segment = seg
        commands, desired_p, desired_v = self.command_interfaces, self.desired_p, self.desired_v
        if t >= times[last]:
            for j in range(len(commands)):
                desired_p[j], desired_v[j] = knots_p[j][last], 0.0
                commands[j].value = desired_p[j]
            self._knots = []  # goal reached: hold
            return return_type.OK
        t0, t1 = times[seg], times[seg + 1]
        for j in range(len(commands)):
            p, v, _ = hermite(t0, knots_p[j][seg], knots_v[j][seg], t1, knots_p[j][seg + 1], knots_v[j][seg + 1], t)
            desired_p[j], desired_v[j] = p, v
            commands[j].value = p
        return return_type.OK


class ScaledJointTrajectoryController(JointTrajectoryController):
    """ur_controllers/ScaledJointTrajectoryController: the UR driver's name for the scaled
    variant, reading speed_scaling/speed_scaling_factor unless configured otherwise."""

    PARAMS = tuple(Param(p.name, "speed_scaling/speed_scaling_factor", p.description)
                   if p.name == "speed_scaling_interface_name" else p for p in JointTrajectoryController.PARAMS)
