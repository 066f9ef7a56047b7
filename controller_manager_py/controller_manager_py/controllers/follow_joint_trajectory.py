"""The ROS side of the joint trajectory controller (executor thread only, never the loop).

On the controller's node (`/<controller>/...`):
  ~/joint_trajectory         trajectory_msgs/JointTrajectory subscription
  ~/follow_joint_trajectory  control_msgs/FollowJointTrajectory action server
  ~/query_state              control_msgs/QueryTrajectoryState service
  ~/controller_state         control_msgs/JointTrajectoryControllerState, `state_publish_rate`,
                             while active (its timer stops while the controller is inactive and
                             starts again within one `action_monitor_rate` tick of activation)

Action semantics (joint_trajectory_controller, Jazzy): a goal is rejected while the
controller is inactive or when its trajectory is refused (joint_trajectory.accept says why
in the log). An accepted goal preempts the running one (which ends ABORTED, INVALID_GOAL,
"preempted"), gets the tolerances of tolerances.goal_tolerances, and ends SUCCEEDED once the
goal tolerances hold after the last point, or ABORTED with PATH_TOLERANCE_VIOLATED /
GOAL_TOLERANCE_VIOLATED (the arm then holds where it is). A cancel of the running goal
holds the arm where it is, or brakes it to a stop with `constraints.decelerate_on_cancel`,
and ends the goal CANCELED.

The loop never waits on this side: it reads one slot and writes a goal's outcome (one
assignment); a timer at `action_monitor_rate` turns outcomes into results and publishes
feedback from the loop's latest snapshot.
"""
from __future__ import annotations

from array import array
from typing import Dict, Tuple

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.task import Future

from . import tolerances as tol
from .trajectory_goal import INVALID_GOAL, GoalRun, TrajectoryError


def to_time(seconds: float):
    from builtin_interfaces.msg import Time
    sec = int(seconds // 1)
    return Time(sec=sec, nanosec=min(int(round((seconds - sec) * 1e9)), 999_999_999))


def from_time(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def fill(point, positions, velocities=None) -> None:
    """Set a JointTrajectoryPoint's positions/velocities (array('d'): no per-element check)."""
    point.positions = array("d", positions)
    point.velocities = array("d", velocities if velocities is not None else ())


class TrajectoryRosInterface:
    def __init__(self, controller, node):
        from control_msgs.action import FollowJointTrajectory
        from control_msgs.msg import JointTrajectoryControllerState
        from control_msgs.srv import QueryTrajectoryState
        from trajectory_msgs.msg import JointTrajectory

        self.c, self.node = controller, node
        self.Action, self.State = FollowJointTrajectory, JointTrajectoryControllerState
        name = node.get_name()  # as ros2_controllers: <controller>/<leaf>, relative to the namespace
        self.subscription = node.create_subscription(JointTrajectory, "~/joint_trajectory",
                                                     controller.on_trajectory, 10)
        self.state_pub = node.create_publisher(JointTrajectoryControllerState, "~/controller_state", 10)
        # one message each, refilled in place (publish serializes at once): building a fresh one
        # costs ~3x more interpreter time, taken from the loop thread's share
        self.state_msg = JointTrajectoryControllerState(joint_names=list(controller.joints))
        self.feedback_msg = FollowJointTrajectory.Feedback(joint_names=list(controller.joints))
        rate = controller.params["state_publish_rate"]
        self.state_timer = node.create_timer(1.0 / rate, self.publish_state) if rate > 0.0 else None
        self.query = node.create_service(QueryTrajectoryState, f"{name}/query_state", self.on_query)
        self._checked: Dict[int, object] = {}  # goal request id -> checked Goal, goal -> accepted callback
        self._runs: Dict[bytes, Tuple[object, GoalRun, Future]] = {}  # goal id -> (handle, run, result future)
        self.server = ActionServer(node, FollowJointTrajectory, f"{name}/follow_joint_trajectory",
                                   execute_callback=self.execute, goal_callback=self.on_goal,
                                   handle_accepted_callback=self.on_accepted, cancel_callback=self.on_cancel)
        self.monitor = node.create_timer(1.0 / controller.params["action_monitor_rate"], self.on_monitor)
        # while the controller is inactive both timers stop (they would wake the executor for
        # nothing); its first update after an activation starts them again through this
        self.activation = node.create_guard_condition(self.on_activation)

    def destroy(self) -> None:
        self.on_monitor()  # deliver the outcomes the loop wrote last
        node = self.node
        for timer in (self.state_timer, self.monitor):
            if timer is not None:
                node.destroy_timer(timer)
        node.destroy_guard_condition(self.activation)
        self.server.destroy()
        node.destroy_service(self.query)
        node.destroy_publisher(self.state_pub)
        node.destroy_subscription(self.subscription)

    # ---- action server ------------------------------------------------------------------------
    def on_goal(self, request) -> GoalResponse:
        c = self.c
        if not c.active:
            c.get_logger().error(f"{c.name}: goal rejected: the controller is not active")
            return GoalResponse.REJECT
        try:
            self._checked[id(request)] = c.accept(request.trajectory)
        except TrajectoryError:
            return GoalResponse.REJECT  # accept() logged why
        return GoalResponse.ACCEPT

    def on_accepted(self, handle) -> None:
        c = self.c
        goal = self._checked.pop(id(handle.request))
        tolerances, problem = tol.goal_tolerances(
            c.default_tolerances, c.joints, handle.request.path_tolerance, handle.request.goal_tolerance,
            from_time(handle.request.goal_time_tolerance))
        if problem:
            c.get_logger().error(f"{c.name}: goal tolerances not used ({problem}); using the defaults")
        goal.run = GoalRun(tolerances, handle)
        future = Future()
        self._runs[bytes(handle.goal_id.uuid)] = (handle, goal.run, future)
        c.offer(goal)  # preempts the running goal
        if not c.active:  # deactivated since on_goal: never leave a goal waiting
            goal.run.finish(GoalRun.ABORTED, INVALID_GOAL, "the controller was deactivated")
        if self.monitor.is_canceled():  # (stopped meanwhile: it delivers the outcome)
            self.monitor.reset()
        handle.execute()

    def on_cancel(self, handle) -> CancelResponse:
        return CancelResponse.ACCEPT  # on_monitor holds the arm and ends the goal

    async def execute(self, handle):
        _, _, future = self._runs[bytes(handle.goal_id.uuid)]
        status, code, text = await future
        if status == GoalRun.SUCCEEDED:
            handle.succeed()
        elif status == GoalRun.CANCELED:
            handle.canceled()
        else:
            handle.abort()
        return self.Action.Result(error_code=code, error_string=text)

    def announce_activation(self) -> None:
        """Loop thread, the controller's first update after activation: wakes the executor
        (a guard condition's trigger, which does not block)."""
        self.activation.trigger()

    def on_activation(self) -> None:
        """Executor, after announce_activation: the timers that stopped while inactive run again."""
        for timer in (self.state_timer, self.monitor):
            if timer is not None and timer.is_canceled():
                timer.reset()

    def on_monitor(self) -> None:
        """Results of finished goals, cancels, feedback of running ones. Stops its own timer
        once the controller is inactive and every goal has its outcome."""
        for goal_id, (handle, run, future) in list(self._runs.items()):
            if run.outcome is None and handle.is_cancel_requested:
                run.finish(GoalRun.CANCELED, 0, "Goal canceled: holding position")
                if self.c.active:
                    self.c.cancel()
            if run.outcome is not None:
                del self._runs[goal_id]
                future.set_result(run.outcome)
            elif run is self.c._run and self.c._snapshot is not None:
                handle.publish_feedback(self.feedback())
        if not self.c.active and not self._runs:
            self.monitor.cancel()

    def feedback(self):
        time, _, desired_p, desired_v, actual_p, actual_v, _ = self.c._snapshot
        msg = self.feedback_msg
        msg.header.stamp = to_time(time)
        self._fill(msg.desired, msg.actual, msg.error, desired_p, desired_v, actual_p, actual_v)
        return msg

    @staticmethod
    def _fill(desired, actual, error, desired_p, desired_v, actual_p, actual_v) -> None:
        fill(desired, desired_p, desired_v)
        fill(actual, actual_p, actual_v)
        error_v = [d - a for d, a in zip(desired_v, actual_v)] if actual_v is not None else None
        fill(error, [d - a for d, a in zip(desired_p, actual_p)], error_v)

    # ---- state and query ----------------------------------------------------------------------
    def publish_state(self) -> None:
        c = self.c
        if not c.active:
            # an inactive controller publishes no state: its timer stops rather than wake the
            # executor for nothing (at 100 Hz, 6-7 % of a core in the simulated arm), and
            # on_activation starts it again
            self.state_timer.cancel()
            return
        snapshot = c._snapshot
        if snapshot is None:
            return
        time, _, desired_p, desired_v, actual_p, actual_v, scale = snapshot
        msg = self.state_msg
        msg.header.stamp = to_time(time)
        msg.speed_scaling_factor = float(scale)
        self._fill(msg.reference, msg.feedback, msg.error, desired_p, desired_v, actual_p, actual_v)
        fill(msg.output, desired_p)  # position commands: what was written
        self.state_pub.publish(msg)

    def on_query(self, request, response):
        c = self.c
        response.name = list(c.joints)
        if not c.active:
            response.success, response.message = False, "the controller is not active"
            return response
        sampled = c.sample(from_time(request.time))
        if sampled is None:
            response.success = False
            response.message = "no active trajectory at that time (before its start, after its end, or none)"
            return response
        response.position, response.velocity, response.acceleration = sampled
        response.success, response.message = True, ""
        return response
