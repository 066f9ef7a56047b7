"""`ros2py action list|info|send_goal` against the trajectory controller on the mock arm."""
import pytest

from harness import ROOT, executable, python_cmd

pytestmark = pytest.mark.integration
ACTION = "/scaled_joint_trajectory_controller/follow_joint_trajectory"
TYPE = "control_msgs/action/FollowJointTrajectory"
JOINTS = "[shoulder_pan_joint, shoulder_lift_joint, elbow_joint, wrist_1_joint, wrist_2_joint, wrist_3_joint]"


def ros2py(launcher, *args, timeout=120):
    return launcher.run(python_cmd("-m", "ball_balance.cli.main", *args), timeout=timeout)


@pytest.fixture
def mock_arm(launcher, graph):
    launcher.start([executable("ros2_control_node"), "--ros-args",
                    "--params-file", str(ROOT / "config" / "ur_controllers.yaml"),
                    "-p", f"robot_description_file:={ROOT / 'config' / 'mock_ur.urdf'}",
                    "-p", "activate_controllers:=[joint_state_broadcaster, scaled_joint_trajectory_controller]",
                    "-p", "inactive_controllers:=[forward_position_controller]"])
    status = f"{ACTION}/_action/status"
    graph.spin_until(lambda: any(n == status for n, _ in graph.node.get_topic_names_and_types()), 60,
                     "the action server")


def goal(positions, seconds=1):
    point = f"{{positions: {positions}, time_from_start: {{sec: {seconds}}}}}"
    return f"{{trajectory: {{joint_names: {JOINTS}, points: [{point}]}}}}"


def test_action_list_and_info_show_the_trajectory_action(launcher, mock_arm):
    listing = ros2py(launcher, "action", "list", "-t", "--spin-time", "30")
    assert listing.returncode == 0, listing.stderr
    assert f"{ACTION} [{TYPE}]" in listing.stdout.splitlines()
    info = ros2py(launcher, "action", "info", ACTION, "-t", "--spin-time", "30")
    assert info.returncode == 0, info.stderr
    lines = info.stdout.splitlines()
    assert lines[0] == f"Action: {ACTION}" and lines[1].startswith("Action clients: "), info.stdout
    # (clients: a test process's earlier clients can linger in discovery on this domain)
    assert lines[-2:] == ["Action servers: 1", f"    /scaled_joint_trajectory_controller [{TYPE}]"], info.stdout


def test_send_goal_prints_feedback_as_it_arrives_and_the_result(launcher, mock_arm):
    sent = ros2py(launcher, "action", "send_goal", ACTION, TYPE, goal("[0.1, -1.5, 1.5, -1.5, 1.5, 0.1]", 2),
                  "--feedback", "--server-timeout", "30")
    assert sent.returncode == 0, sent.stdout + sent.stderr
    out = sent.stdout
    assert "Goal accepted with ID: " in out
    feedback_at, result_at = out.index("Feedback:"), out.index("Result:")
    assert feedback_at < result_at and "desired:" in out[feedback_at:result_at]
    assert "error_code: 0" in out[result_at:]
    assert out.rstrip().endswith("Goal finished with status: SUCCEEDED")


def test_send_goal_reports_a_rejected_goal_with_a_non_zero_exit(launcher, mock_arm):
    unknown_joint = goal("[0.1, -1.5, 1.5, -1.5, 1.5, 0.1]").replace("wrist_3_joint", "knee_joint")
    sent = ros2py(launcher, "action", "send_goal", ACTION, TYPE, unknown_joint, "--server-timeout", "30")
    assert sent.returncode == 1 and "Goal was rejected." in sent.stdout
    wrong = ros2py(launcher, "action", "send_goal", ACTION, "control_msgs/action/NoSuchAction", "{}")
    assert wrong.returncode == 1 and "no action 'NoSuchAction'" in wrong.stderr
