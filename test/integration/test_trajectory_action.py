"""FollowJointTrajectory on the simulated arm, as MoveIt or `ros2 action send_goal` use it:
a goal reaches its points and succeeds, a goal whose tolerances cannot be met is aborted
and the arm holds, a new goal preempts the running one, and a trajectory to an unreachable
50 rad is refused so that the controller's state never leaves the arm's."""
import numpy as np
import pytest
from builtin_interfaces.msg import Duration, Time
from control_msgs.action import FollowJointTrajectory
from control_msgs.msg import JointTolerance, JointTrajectoryControllerState
from control_msgs.srv import QueryTrajectoryState
from rclpy.action import ActionClient
from sensor_msgs.msg import JointState
from test_sim_arm import START_TIMEOUT, joint_positions, start_sim
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ball_balance import robot

pytestmark = pytest.mark.integration
CONTROLLER = "/scaled_joint_trajectory_controller"
ACTION = f"{CONTROLLER}/follow_joint_trajectory"
HOME = np.array(robot.HOME_POSITIONS_RAD)
SUCCEEDED, CANCELED, ABORTED = 4, 5, 6  # action_msgs/GoalStatus
TIMEOUT = 60.0  # deadlines, generous for 2 busy cores: the simulation runs slower than real time then


def duration(seconds: float) -> Duration:
    return Duration(sec=int(seconds), nanosec=int(round((seconds % 1) * 1e9)))


def trajectory(points) -> JointTrajectory:
    return JointTrajectory(joint_names=list(robot.JOINT_NAMES), points=[
        JointTrajectoryPoint(positions=[float(v) for v in p], time_from_start=duration(t)) for t, p in points])


def tolerances(position: float):
    return [JointTolerance(name=j, position=position) for j in robot.JOINT_NAMES]


@pytest.fixture
def arm(launcher, graph, tmp_path):
    """The simulated arm with the trajectory controller active, and an action client."""
    start_sim(launcher, tmp_path, trajectory=True, camera_enabled=False)
    graph.collect(JointState, "/joint_states", timeout=START_TIMEOUT)
    client = ActionClient(graph.node, FollowJointTrajectory, ACTION)
    graph.spin_until(client.server_is_ready, TIMEOUT, f"the action server {ACTION}")
    yield client
    client.destroy()


def send(graph, client, goal):
    sent = client.send_goal_async(goal)
    graph.spin_until(sent.done, TIMEOUT, "the goal response")
    return sent.result()


def result_of(graph, handle):
    result = handle.get_result_async()
    graph.spin_until(result.done, TIMEOUT, "the goal result")
    return result.result()


def measured(graph) -> np.ndarray:
    return joint_positions(graph.collect(JointState, "/joint_states", timeout=TIMEOUT)[0])


def stamp_s(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def test_two_point_goal_succeeds_with_the_arm_at_the_goal(arm, graph):
    step = np.array([0.05, 0.0, 0.0, -0.05, 0.05, 0.05])
    goal = FollowJointTrajectory.Goal(trajectory=trajectory([(0.6, HOME + step), (1.2, HOME + 2 * step)]),
                                      goal_tolerance=tolerances(0.01), goal_time_tolerance=duration(5.0))
    handle = send(graph, arm, goal)
    assert handle.accepted
    result = result_of(graph, handle)
    assert (result.status, result.result.error_code) == (SUCCEEDED, FollowJointTrajectory.Result.SUCCESSFUL), \
        result.result.error_string
    assert np.allclose(measured(graph), HOME + 2 * step, atol=0.01)


def test_goal_whose_path_tolerance_cannot_be_met_is_aborted_and_the_arm_holds(arm, graph):
    target = HOME + np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.4])
    goal = FollowJointTrajectory.Goal(trajectory=trajectory([(1.5, target)]), path_tolerance=tolerances(1e-7))
    handle = send(graph, arm, goal)
    assert handle.accepted
    result = result_of(graph, handle)
    assert (result.status, result.result.error_code) == \
        (ABORTED, FollowJointTrajectory.Result.PATH_TOLERANCE_VIOLATED), result.result.error_string
    first = graph.collect(JointState, "/joint_states", timeout=TIMEOUT)[0]
    later = graph.collect(JointState, "/joint_states", timeout=TIMEOUT,
                          predicate=lambda m: stamp_s(m) >= stamp_s(first) + 1.0)[0]
    assert np.allclose(joint_positions(later), joint_positions(first), atol=0.01)  # held, not moving on
    assert joint_positions(later)[5] < target[5] - 0.2  # stopped well before the goal


def test_second_goal_preempts_the_first(arm, graph):
    far = HOME + np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.5])
    near = HOME + np.array([0.0, 0.0, 0.0, 0.0, 0.0, -0.05])
    feedback = []
    sent = arm.send_goal_async(FollowJointTrajectory.Goal(trajectory=trajectory([(4.0, far)])),
                               feedback_callback=feedback.append)
    graph.spin_until(lambda: sent.done() and feedback, TIMEOUT, "the first goal running")
    first = sent.result()
    second = send(graph, arm, FollowJointTrajectory.Goal(trajectory=trajectory([(1.0, near)]),
                                                         goal_tolerance=tolerances(0.01),
                                                         goal_time_tolerance=duration(5.0)))
    assert second.accepted
    first_result = result_of(graph, first)
    assert (first_result.status, first_result.result.error_code) == \
        (ABORTED, FollowJointTrajectory.Result.INVALID_GOAL)
    assert "preempted" in first_result.result.error_string
    second_result = result_of(graph, second)
    assert second_result.status == SUCCEEDED, second_result.result.error_string
    assert np.allclose(measured(graph), near, atol=0.01)


def test_query_state_samples_the_goal_and_cancel_holds_the_arm(arm, graph):
    target = HOME + np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.5])
    feedback = []
    sent = arm.send_goal_async(FollowJointTrajectory.Goal(trajectory=trajectory([(4.0, target)])),
                               feedback_callback=feedback.append)
    graph.spin_until(lambda: sent.done() and len(feedback) >= 3, TIMEOUT, "the goal running")
    handle = sent.result()
    # ~/query_state samples the running trajectory at a time of the manager's clock
    now = feedback[-1].feedback.header.stamp
    query = QueryTrajectoryState.Request(time=Time(sec=now.sec + 1, nanosec=now.nanosec))
    sampled = graph.call(QueryTrajectoryState, f"{CONTROLLER}/query_state", query, timeout=TIMEOUT)
    assert sampled.success, sampled.message
    assert list(sampled.name) == list(robot.JOINT_NAMES)
    assert feedback[-1].feedback.desired.positions[5] < sampled.position[5] < target[5]
    canceling = handle.cancel_goal_async()
    graph.spin_until(canceling.done, TIMEOUT, "the cancel response")
    assert canceling.result().goals_canceling
    assert result_of(graph, handle).status == CANCELED
    first = graph.collect(JointState, "/joint_states", timeout=TIMEOUT)[0]
    later = graph.collect(JointState, "/joint_states", timeout=TIMEOUT,
                          predicate=lambda m: stamp_s(m) >= stamp_s(first) + 1.0)[0]
    assert np.allclose(joint_positions(later), joint_positions(first), atol=0.01)
    assert joint_positions(later)[5] < target[5] - 0.1


def test_unreachable_50_rad_is_refused_and_the_controller_state_stays_with_the_arm(arm, graph):
    """A goal of 50 rad on the simulated arm, then a valid trajectory home."""
    away = HOME + np.array([0.2, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert result_of(graph, send(graph, arm, FollowJointTrajectory.Goal(
        trajectory=trajectory([(1.0, away)]), goal_tolerance=tolerances(0.01),
        goal_time_tolerance=duration(5.0)))).status == SUCCEEDED
    unreachable = away.copy()
    unreachable[0] = 50.0
    assert not send(graph, arm, FollowJointTrajectory.Goal(trajectory=trajectory([(2.0, unreachable)]))).accepted
    pub = graph.node.create_publisher(JointTrajectory, f"{CONTROLLER}/joint_trajectory", 10)
    graph.spin_until(lambda: pub.get_subscription_count() > 0, TIMEOUT, "the trajectory subscription")
    pub.publish(trajectory([(2.0, unreachable)]))

    def consistent(state: JointTrajectoryControllerState) -> bool:
        return np.allclose(state.reference.positions, state.feedback.positions, atol=0.01)

    states = []
    sub = graph.node.create_subscription(JointTrajectoryControllerState, f"{CONTROLLER}/controller_state",
                                         states.append, 10)
    graph.spin_until(lambda: len(states) > 1 and stamp_s(states[-1]) >= stamp_s(states[0]) + 1.5, TIMEOUT,
                     "1.5 s of controller state after the 50 rad trajectory")
    graph.node.destroy_subscription(sub)
    assert all(consistent(s) for s in states)
    assert all(abs(s.reference.positions[0] - away[0]) < 0.01 for s in states)  # never set out for 50 rad
    home = result_of(graph, send(graph, arm, FollowJointTrajectory.Goal(
        trajectory=trajectory([(1.0, HOME)]), goal_tolerance=tolerances(0.01), goal_time_tolerance=duration(5.0))))
    assert home.status == SUCCEEDED, home.result.error_string
    assert np.allclose(measured(graph), HOME, atol=0.01)
    (state,) = graph.collect(JointTrajectoryControllerState, f"{CONTROLLER}/controller_state", timeout=TIMEOUT)
    assert consistent(state) and np.allclose(state.reference.positions, HOME, atol=0.01)
