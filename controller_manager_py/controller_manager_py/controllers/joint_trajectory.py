"""joint_trajectory_controller/JointTrajectoryController (position command interface).

Inputs (executor thread, never the loop):
  - topic `~/joint_trajectory` (trajectory_msgs/JointTrajectory);
  - action `~/follow_joint_trajectory` (control_msgs/FollowJointTrajectory), see
    follow_joint_trajectory.py: tolerances per goal, feedback, result; a new goal (or a
    topic trajectory) preempts the running goal, a cancel holds the arm where it is;
  - service `~/query_state` (control_msgs/QueryTrajectoryState): the active trajectory
    sampled at a time.
Output: `~/controller_state` (control_msgs/JointTrajectoryControllerState) at
`state_publish_rate`, from a timer (ros2_control publishes in update(); a Python
publish in the loop would cost the loop more than the update itself).

Every trajectory is checked at the edge: joint names known and unique (all of `joints`
unless allow_partial_joints_goal), one finite position per joint per point, velocities
empty or complete, time_from_start strictly increasing, not ending in the past (a
stamped trajectory, as ros2_controllers), and every point within the
joints' limits (tolerances.check_limits: position range, waypoint velocity). A bad trajectory is
refused with one throttled warning and counted (an action goal is rejected); the running
one continues. A good one is reordered to the controller's joint order and handed to
update() through one slot (one reference assignment).

update() (real-time) starts a new trajectory from the measured state (Jazzy's default; with
`interpolate_from_desired_state` from the desired state), so the controller's notion of
where the arm is cannot drift from where it is. Waypoints with velocities use them (cubic
Hermite); position-only waypoints get velocities from the clamped cubic spline. Trajectory
time runs at `period * speed_scaling` when `speed_scaling_interface_name` names a state
interface (the UR driver's speed_scaling/speed_scaling_factor, 0..1): the scaled
controller. A header stamp of zero starts the trajectory now; otherwise at the stamp
(manager clock). While it runs the path tolerances are checked, after its last point the
goal tolerances (within goal_time); a violation holds the arm where it is (and aborts the
goal). An empty trajectory stops: hold where the arm is. With
`constraints.decelerate_on_cancel` (and every joint's `max_deceleration_on_cancel` > 0, and
velocity states) a cancel or an abort brakes each joint at that deceleration to where it
comes to rest instead (tolerances.stopping_profile), as ros2_controllers does. The desired positions pass
through the shared JointLimiter (manager/joint_limits.py: position range, velocity,
acceleration) before they are commanded, so what the controller believes it commands is
what the joints get; clamps are counted (`clamped_commands`) and logged, throttled.
Limits come from the robot description the manager hands its controllers.
"""
from __future__ import annotations

import math
from typing import Dict, List, Mapping, Optional, Tuple

from ..controller_interface.base import (
    ControllerInterface,
    InterfaceConfiguration,
    interface_configuration_type,
)
from ..hardware_interface.types import CallbackReturn, JointLimits, State, return_type
from ..manager.joint_limits import JointLimiter, limits_from_description
from ..manager.throttle import Throttle
from ..parameters import Param, declare_parameters
from . import tolerances as tol
from .forward_command import _non_empty
from .spline import clamped_spline_velocities, hermite
from .trajectory_goal import (  # noqa: F401 (re-exported: the controller's public names)
    GOAL_TOLERANCE_VIOLATED,
    INVALID_GOAL,
    PATH_TOLERANCE_VIOLATED,
    SUCCESSFUL,
    Goal,
    GoalRun,
    TrajectoryError,
    check_trajectory,
)

JOINTS = Param("joints", [""], "controlled joints", check=_non_empty, user_facing=True)


class JointTrajectoryController(ControllerInterface):
    PARAMS = (
        JOINTS,
        Param("command_interfaces", ["position"], "command interfaces (position supported)",
              check=lambda v: None if list(v) == ["position"] else "only [position] is supported", user_facing=True),
        Param("state_interfaces", ["position", "velocity"], "state interfaces read", user_facing=True),
        Param("allow_partial_joints_goal", False, "accept trajectories naming only some joints", user_facing=True),
        Param("speed_scaling_interface_name", "", "state interface scaling trajectory time (scaled JTC)",
              user_facing=True),
        Param("interpolate_from_desired_state", False,
              "start a new trajectory from the desired state instead of the measured one"),
        Param("state_publish_rate", 50.0, "rate of ~/controller_state (0 = not published)", unit="Hz",
              min=0.0, max=1000.0, user_facing=True),
        Param("action_monitor_rate", 20.0, "rate at which action goals get feedback and results", unit="Hz",
              min=1.0, max=1000.0),
    )

    # ---- parameters: the per-joint constraints depend on `joints` ------------------------------
    def param_schema(self) -> List[Param]:  # type: ignore[override]  # needs the instance: joints
        return [*super().param_schema(), *tol.constraint_params(self._schema_joints)]

    def load_params(self, values: Optional[Mapping] = None) -> None:
        node = self.get_node()
        if node is not None and values is None:
            joints = (node.get_parameter(JOINTS.name).value if node.has_parameter(JOINTS.name)
                      else declare_parameters(node, [JOINTS])[JOINTS.name])
        else:
            joints = (values or {}).get(JOINTS.name, JOINTS.default)
        self._schema_joints = [j for j in JOINTS.validate(joints) if j]
        super().load_params(values)

    _schema_joints: List[str] = []

    # ---- lifecycle (executor thread) ---------------------------------------------------------
    def on_configure(self, previous_state: State) -> CallbackReturn:
        self.joints = [j for j in self.params["joints"] if j]
        self.state_names = list(self.params["state_interfaces"])
        if "position" not in self.state_names:
            self.get_logger().error(f"{self.name}: state_interfaces must include position")
            return CallbackReturn.ERROR
        self.scaling_name = self.params["speed_scaling_interface_name"]
        self.default_tolerances = tol.default_tolerances(self.joints, self.params)
        self.stop_decelerations = self._stop_decelerations()
        self._stopping = False
        self.limits: Dict[str, JointLimits] = self._joint_limits()
        self.limiter = JointLimiter(self.joints, self.limits, self.get_logger(), self.name)
        self.throttle = Throttle(self.get_logger())
        self.refused = 0
        self.aborted = 0
        self._slot: Optional[Goal] = None
        self._taken: Optional[Goal] = None
        self._run: Optional[GoalRun] = None  # the goal the loop is following
        self._snapshot = None
        self.traj_time = 0.0
        self.scale = 1.0
        self._step = 0.0
        self.holding = True
        n = len(self.joints)
        self.desired_p = [math.nan] * n
        self.desired_v = [0.0] * n
        self.actual_p = [math.nan] * n
        self.actual_v = [0.0] * n
        self._knots: List[Tuple[List[float], List[List[float]], List[List[float]]]] = []
        self.introspection.clear()  # (re)configure: the getters read the live attributes
        self.register_introspection("trajectory_time", lambda: self.traj_time)
        self.register_introspection("refused_trajectories", lambda: float(self.refused))
        self.register_introspection("clamped_commands", lambda: float(self.limiter.clamped))
        self.register_introspection("aborted_goals", lambda: float(self.aborted))
        for j, joint in enumerate(self.joints):
            self.register_introspection(f"{joint}.desired_position", lambda j=j: self.desired_p[j])
            self.register_introspection(f"{joint}.desired_velocity", lambda j=j: self.desired_v[j])
        self.ros = None
        self._announce_activation = False
        if self.get_node() is not None:
            from .follow_joint_trajectory import TrajectoryRosInterface
            self.ros = TrajectoryRosInterface(self, self.get_node())
        return CallbackReturn.SUCCESS

    def _stop_decelerations(self) -> Optional[List[float]]:
        """Each joint's max_deceleration_on_cancel when decelerate_on_cancel can be honoured,
        else None (hold where the arm is), with one error line saying why not."""
        if not self.params["constraints.decelerate_on_cancel"]:
            return None
        decelerations = [self.params[f"constraints.{j}.max_deceleration_on_cancel"] for j in self.joints]
        missing = [j for j, a in zip(self.joints, decelerations) if a <= 0.0]
        problem = (f"max_deceleration_on_cancel not set (> 0) for {missing}" if missing else
                   None if "velocity" in self.state_names else "no velocity state interface")
        if problem:
            self.get_logger().error(f"{self.name}: decelerate_on_cancel: {problem}; holding position on cancel")
            return None
        return decelerations

    def _joint_limits(self) -> Dict[str, JointLimits]:
        """The limits of our joints from the robot description the manager hands its
        controllers (ros2_control's get_robot_description()); none without one."""
        urdf = self.get_robot_description()
        if not urdf:
            self.get_logger().warning(f"{self.name}: no robot description: trajectories are not checked against "
                                      "joint limits here (the manager's limits stage still applies)")
            return {}
        try:
            return tol.limits_of(self.joints, limits_from_description(urdf))
        except ValueError as error:  # DescriptionError
            self.get_logger().error(f"{self.name}: joint limits not read from the robot description: {error}")
            return {}

    @property
    def clamped(self) -> int:
        """Desired positions the joint limits changed (counted by the limiter)."""
        return self.limiter.clamped

    def on_cleanup(self, previous_state: State) -> CallbackReturn:
        if self.ros is not None:
            self.ros.destroy()
            self.ros = None
        return CallbackReturn.SUCCESS

    def command_interface_configuration(self) -> InterfaceConfiguration:
        return InterfaceConfiguration(interface_configuration_type.INDIVIDUAL, [f"{j}/position" for j in self.joints])

    def state_interface_configuration(self) -> InterfaceConfiguration:
        names = [f"{j}/{i}" for j in self.joints for i in self.state_names]
        if self.scaling_name:
            names.append(self.scaling_name)
        return InterfaceConfiguration(interface_configuration_type.INDIVIDUAL, names)

    @property
    def active(self) -> bool:
        return self.lifecycle_state == State.ACTIVE

    # ---- edge: executor thread ----------------------------------------------------------------
    def accept(self, msg, run: Optional[GoalRun] = None) -> Goal:
        """Check a JointTrajectory (joints, values, limits); raises TrajectoryError. Counted
        and logged (throttled) when refused."""
        try:
            goal = check_trajectory(msg, self.joints, self.params["allow_partial_joints_goal"])
            snapshot = self._snapshot
            if goal.stamp > 0.0 and goal.times and snapshot is not None and goal.stamp + goal.times[-1] < snapshot[0]:
                raise TrajectoryError(f"it ends {snapshot[0] - goal.stamp - goal.times[-1]:.3f} s in the past "
                                      "(header stamp + last time_from_start; a zero stamp means now)")
            if self.limits and goal.times:
                problem = tol.check_limits(self.joints, self.limits, goal.positions, goal.velocities, goal.mask)
                if problem:
                    raise TrajectoryError(f"beyond the joint limits: {problem}")
        except TrajectoryError as error:
            self.refused += 1
            self.throttle.warn("refused", f"{self.name}: trajectory refused: {error} (refused so far: {self.refused})")
            raise
        goal.run = run
        return goal

    def offer(self, goal: Goal) -> None:
        """Hand a checked trajectory to the loop; it replaces (preempts) the current one."""
        previous = self._slot
        if previous is not None and previous.run is not None and previous.run is not goal.run:
            previous.run.finish(GoalRun.ABORTED, INVALID_GOAL, "Current goal preempted by new incoming action.")
        self._slot = goal

    def hold(self) -> None:
        """Stop where the arm is: an empty trajectory."""
        self.offer(Goal([], [], None, 0.0, [True] * len(self.joints)))

    def cancel(self) -> None:
        """A cancelled goal: brake to a stop (decelerate_on_cancel) or hold where the arm is."""
        self.offer(Goal([], [], None, 0.0, [True] * len(self.joints), decelerate=True))

    def on_trajectory(self, msg) -> bool:
        """~/joint_trajectory callback: a trajectory without a goal (preempts a running goal)."""
        try:
            goal = self.accept(msg)
        except TrajectoryError:
            return False
        self.offer(goal)
        return True

    def sample(self, time: float) -> Optional[Tuple[List[float], List[float], List[float]]]:
        """(positions, velocities, accelerations) of the active trajectory at manager time
        `time`, or None outside it (executor thread: reads one immutable knots tuple)."""
        knots, snapshot = self._knots, self._snapshot
        if not knots or snapshot is None:
            return None
        times, knots_p, knots_v = knots[0]
        t = snapshot[1] + (time - snapshot[0]) * snapshot[6]  # trajectory time at `time`
        if t < times[0] or t > times[-1]:
            return None
        seg = 0
        while seg < len(times) - 2 and t >= times[seg + 1]:
            seg += 1
        values = [hermite(times[seg], knots_p[j][seg], knots_v[j][seg], times[seg + 1], knots_p[j][seg + 1],
                          knots_v[j][seg + 1], t) for j in range(len(self.joints))]
        return [v[0] for v in values], [v[1] for v in values], [v[2] for v in values]

    # ---- lifecycle in the loop ------------------------------------------------------------------
    def on_activate(self, previous_state: State) -> CallbackReturn:
        n, states = len(self.joints), self.state_interfaces
        per_joint = len(self.state_names)
        self._pos = [states[k * per_joint + self.state_names.index("position")] for k in range(n)]
        self._vel = ([states[k * per_joint + self.state_names.index("velocity")] for k in range(n)]
                     if "velocity" in self.state_names else None)
        self._scaling = states[-1] if self.scaling_name else None
        self._read_state()
        self._end_pending_goals("Current goal cancelled: the controller was (re)activated.")
        self._hold_here()
        self.traj_time = 0.0
        self._announce_activation = True   # to the ROS side, from the first update (active by then)
        return CallbackReturn.SUCCESS

    def on_deactivate(self, previous_state: State) -> CallbackReturn:
        self._end_pending_goals("Current goal cancelled during deactivate transition.")
        self._knots = []
        return CallbackReturn.SUCCESS

    def _end_pending_goals(self, why: str) -> None:
        """Abort the goals handed over but not finished (a goal never hangs on a switch)."""
        for goal in (self._slot, self._taken):
            if goal is not None and goal.run is not None:
                goal.run.finish(GoalRun.ABORTED, INVALID_GOAL, why)
        self._slot = self._taken = None
        self._run = None

    # ---- real-time ------------------------------------------------------------------------------
    def _read_state(self) -> None:
        actual_p, actual_v = self.actual_p, self.actual_v
        for j, handle in enumerate(self._pos):
            actual_p[j] = handle.value
        if self._vel is not None:
            for j, handle in enumerate(self._vel):
                actual_v[j] = handle.value

    def _hold_here(self) -> None:
        """Hold the measured position (ros2_controllers' set_hold_position)."""
        self._knots = []
        self.holding = True
        self._stopping = False
        self.limiter.reset(self.actual_p)
        for j, handle in enumerate(self.command_interfaces):
            p = self.actual_p[j]
            self.desired_p[j], self.desired_v[j] = p, 0.0
            handle.value = p

    def _start(self, goal: Goal, time: float) -> None:
        """Build knots from the current state to the goal's future waypoints."""
        self._run = goal.run
        self.traj_time = time - goal.stamp if goal.stamp > 0.0 else 0.0
        if abs(self.traj_time) > 5.0:  # most likely wall-clock stamps against simulated time, or the reverse
            self.throttle.warn("stamp", f"{self.name}: trajectory stamped {-self.traj_time:+.1f} s from now; "
                                        "check use_sim_time (a zero stamp starts it on arrival)")
        if not goal.times:  # empty trajectory: stop here
            # the desired state is last cycle's command: this cycle's sample is one step on
            self._stop_here(self._step) if goal.decelerate else self._hold_here()
            return
        from_desired = self.params["interpolate_from_desired_state"] and not self.holding
        start_p = self.desired_p if from_desired else self.actual_p
        start_v = self.desired_v if from_desired or self._vel is None else self.actual_v
        first = next((k for k, t in enumerate(goal.times) if t > self.traj_time), len(goal.times))
        if first == len(goal.times):  # all in the past: go to the last point
            first = len(goal.times) - 1
            t0 = goal.times[first] - 1e-3
        else:
            t0 = self.traj_time
        times = [t0, *goal.times[first:]]
        knots_p, knots_v = [], []
        for j in range(len(self.joints)):
            p = [start_p[j]] + [goal.positions[k][j] if goal.mask[j] else start_p[j]
                                for k in range(first, len(goal.times))]
            if goal.velocities is not None:
                v = [start_v[j]] + [goal.velocities[k][j] for k in range(first, len(goal.times))]
            else:
                v = clamped_spline_velocities(times, p, start_v[j], 0.0)
            knots_p.append(p)
            knots_v.append(v)
        self._begin(times, knots_p, knots_v, start_p, start_v)

    def _begin(self, times, knots_p, knots_v, start_p, start_v, stopping: bool = False) -> None:
        self._knots = [(times, knots_p, knots_v)]
        self.limiter.reset(start_p, start_v)
        self._segment = 0
        self._first_sample = True
        self.holding = False
        self._stopping = stopping

    def _stop_here(self, elapsed: float = 0.0) -> None:
        """Brake each joint to rest at its max_deceleration_on_cancel, or hold (not configured).
        elapsed: trajectory time since the desired state was commanded (0 within this cycle)."""
        decelerations = self.stop_decelerations
        if decelerations is None or self._vel is None:
            self._hold_here()
            return
        # from the commanded state: the measured one lags it by the arm's following delay, and
        # braking from there would first step the command back (the arm stalls a cycle, then moves on)
        start_p, start_v = (self.actual_p, self.actual_v) if self.holding else (self.desired_p, self.desired_v)
        times, knots_p, knots_v = tol.stopping_profile(start_p, start_v, decelerations)
        if len(times) < 2:  # nothing moves
            self._hold_here()
            return
        self._begin(times, knots_p, knots_v, list(start_p), list(start_v), stopping=True)
        self.traj_time = elapsed

    def _abort(self, code: int, text: str) -> None:
        """A tolerance violation: hold where the arm is; report it on the goal, if any."""
        self.aborted += 1
        run = self._run
        if run is not None:
            run.finish(GoalRun.ABORTED, code, text)
            self._run = None
        self.throttle.warn(f"abort{code}", f"{self.name}: holding position: {text}")
        self._stop_here()

    def update(self, time: float, period: float) -> return_type:
        if self._announce_activation:
            self._announce_activation = False
            if self.ros is not None:
                self.ros.announce_activation()
        self._read_state()
        scale = 1.0
        if self._scaling is not None:
            scale = self._scaling.value
            scale = 1.0 if scale != scale else (0.0 if scale < 0.0 else scale)
        self.scale = scale
        self._step = period * scale
        goal = self._slot
        if goal is not None and goal is not self._taken:
            self._taken = goal
            self._start(goal, time)
        elif self._knots:
            self.traj_time += period * scale
        if self._knots:
            self._follow(period)
        self._snapshot = (time, self.traj_time, tuple(self.desired_p), tuple(self.desired_v),
                          tuple(self.actual_p), tuple(self.actual_v) if self._vel is not None else None, scale)
        return return_type.OK

    def _follow(self, period: float) -> None:
        times, knots_p, knots_v = self._knots[0]
        t = self.traj_time
        if t < times[0]:
            return  # stamped in the future: hold
        last = len(times) - 1
        seg = self._segment
        while seg < last - 1 and t >= times[seg + 1]:
            seg += 1
        self._segment = seg
        commands, desired_p, desired_v = self.command_interfaces, self.desired_p, self.desired_v
        after_end = t >= times[last]
        for j in range(len(commands)):
            if after_end:
                desired_p[j], desired_v[j] = knots_p[j][last], 0.0
            else:
                desired_p[j], desired_v[j], _ = hermite(times[seg], knots_p[j][seg], knots_v[j][seg], times[seg + 1],
                                                        knots_p[j][seg + 1], knots_v[j][seg + 1], t)
        self._held_back = False
        if self.limits:
            # what the joints can follow: the desired state is what is commanded, never beyond
            limited = self.limiter.limit_positions(desired_p, period)
            self._held_back = any(abs(a - b) > 1e-9 for a, b in zip(limited, desired_p))
            desired_p[:] = limited
        for j in range(len(commands)):
            commands[j].value = desired_p[j]
        self._check_tolerances(t - times[last], not after_end or self._first_sample)
        self._first_sample = False

    def _check_tolerances(self, after_end: float, moving: bool) -> None:
        """Path tolerances while moving, goal tolerances after the last point (Jazzy's rules)."""
        if self._stopping:  # braking after a cancel or an abort: nothing to check, rest at its end
            if after_end >= 0.0 and not self._held_back:
                self._knots, self._stopping = [], False
            return
        run = self._run
        tolerances = run.tolerances if run is not None else self.default_tolerances
        n = len(self.joints)
        error_p = [self.desired_p[j] - self.actual_p[j] for j in range(n)]
        error_v = [self.desired_v[j] - self.actual_v[j] for j in range(n)] if self._vel is not None else None
        if moving:
            problem = tol.violation(self.joints, tolerances.path, error_p, error_v)
            if problem:
                self._abort(PATH_TOLERANCE_VIOLATED, f"Aborted due to path tolerance violation: {problem}")
            return
        if after_end < 0.0 or self._held_back:
            return  # not at the end yet (or the limits still hold the desired state back)
        problem = tol.violation(self.joints, tolerances.goal, error_p, error_v)
        if problem is None:
            if run is not None:
                run.finish(GoalRun.SUCCEEDED, SUCCESSFUL, "Goal successfully reached!")
                self._run = None
            self._knots = []  # reached: hold the last point (desired_p keeps it)
        elif tolerances.goal_time > 0.0 and after_end > tolerances.goal_time:
            self._abort(GOAL_TOLERANCE_VIOLATED, f"Aborted due to goal_time_tolerance exceeding by "
                                                 f"{after_end - tolerances.goal_time:.3f} s: {problem}")


class ScaledJointTrajectoryController(JointTrajectoryController):
    """ur_controllers/ScaledJointTrajectoryController: the UR driver's name for the scaled
    variant, reading speed_scaling/speed_scaling_factor unless configured otherwise."""

    PARAMS = tuple(Param(p.name, "speed_scaling/speed_scaling_factor", p.description)
                   if p.name == "speed_scaling_interface_name" else p for p in JointTrajectoryController.PARAMS)
