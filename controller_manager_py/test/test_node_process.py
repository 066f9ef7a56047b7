"""ros2_control_node as a process: the mock arm (mock_ur.urdf) with the joint state broadcaster
and the joint trajectory controller, driven over DDS from this test. Runs whichever copy of
controller_manager_py this interpreter imports (the source folder or an installed one)."""
import fcntl
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
import rclpy
import yaml
from builtin_interfaces.msg import Duration
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

HERE = Path(__file__).resolve().parent
JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
          "wrist_3_joint"]
TARGET = [0.2, -1.3, 1.2, -1.4, 1.4, 0.3]
PARAMS = f"""controller_manager:
  ros__parameters:
    update_rate: 200
    joint_state_broadcaster:
      type: joint_state_broadcaster/JointStateBroadcaster
    joint_trajectory_controller:
      type: joint_trajectory_controller/JointTrajectoryController
    activate_controllers: [joint_state_broadcaster, joint_trajectory_controller]
    thread_priority: 0
    loop:
      executor_thread_priority: 0
joint_trajectory_controller:
  ros__parameters:
    joints: [{", ".join(JOINTS)}]
    command_interfaces: [position]
    state_interfaces: [position, velocity]
"""
# ROS domains of this package's process tests: above the range the application's tests use
DOMAINS = (231, 232)


@pytest.fixture
def domain_id():
    """A ROS domain no other run of this test uses now (a lock file per domain)."""
    for domain in DOMAINS:
        handle = open(Path(tempfile.gettempdir()) / f"controller_manager_py_domain_{domain}.lock", "w")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        try:
            yield domain
        finally:
            handle.close()
        return
    pytest.skip(f"every test domain {DOMAINS} is in use")


def spin_until(executor, condition, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError(f"no {what} within {timeout_s:g} s")
        executor.spin_once(timeout_sec=0.05)


def test_ros2_control_node_moves_the_mock_arm_along_a_trajectory(domain_id, tmp_path):
    params = tmp_path / "controllers.yaml"
    params.write_text(PARAMS)
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    env.pop("ROS_LOCALHOST_ONLY", None)
    log = open(tmp_path / "ros2_control_node.log", "wb")
    node_process = subprocess.Popen(
        [sys.executable, "-m", "controller_manager_py.ros2_control_node", "--ros-args", "--params-file",
         str(params), "-p", f"robot_description_file:={HERE / 'mock_ur.urdf'}"],
        stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id, args=[])
    try:
        node = rclpy.create_node("test_node_process", context=context)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        latest = {}
        node.create_subscription(JointState, "/joint_states",
                                 lambda m: latest.update(zip(m.name, m.position)), 10)
        publisher = node.create_publisher(JointTrajectory, "/joint_trajectory_controller/joint_trajectory", 10)
        try:
            spin_until(executor, lambda: len(latest) == len(JOINTS), 60.0, "/joint_states from the broadcaster")
            spin_until(executor, lambda: publisher.get_subscription_count() > 0, 30.0,
                       "subscriber of the trajectory controller")
        except TimeoutError as error:
            raise AssertionError(f"{error}\n{(tmp_path / 'ros2_control_node.log').read_text()}") from None
        trajectory = JointTrajectory(joint_names=JOINTS, points=[
            JointTrajectoryPoint(positions=TARGET, time_from_start=Duration(sec=1))])
        publisher.publish(trajectory)
        spin_until(executor, lambda: all(math.isclose(latest[j], t, abs_tol=1e-3) for j, t in zip(JOINTS, TARGET)),
                   30.0, "arrival at the trajectory's end")
        executor.shutdown()
        node.destroy_node()
    finally:
        context.try_shutdown()
        os.killpg(node_process.pid, signal.SIGINT)
        try:
            node_process.wait(timeout=15)
        except subprocess.TimeoutExpired:
            os.killpg(node_process.pid, signal.SIGKILL)
            node_process.wait()
        log.close()
    assert node_process.returncode == 0, (tmp_path / "ros2_control_node.log").read_text()


@pytest.mark.parametrize("extra, controller_values, code, named", [
    ([], {}, 0, ""),
    (["-p", "update_rate:=0"], {}, 2, "update_rate"),
    # the controllers it would start are configured too: a bad value, an interface it cannot claim,
    # a misspelt name (with unknown_parameters: error)
    ([], {"state_publish_rate": -1.0}, 2, "state_publish_rate"),
    ([], {"joints": ["nonsense_joint"]}, 2, "nonsense_joint"),
    ([], {"unknown_parameters": "error", "goal_tolerance": 0.1}, 2, "goal_tolerance")])
def test_check_params_builds_the_node_and_ends_without_spinning(tmp_path, extra, controller_values, code, named):
    values = yaml.safe_load(PARAMS)
    values["joint_trajectory_controller"]["ros__parameters"].update(controller_values)
    params = tmp_path / "controllers.yaml"
    params.write_text(yaml.safe_dump(values))
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF"}  # seen by no one: no domain needed
    env.pop("ROS_LOCALHOST_ONLY", None)
    result = subprocess.run(
        [sys.executable, "-m", "controller_manager_py.ros2_control_node", "--check-params", "--ros-args",
         "--params-file", str(params), "-p", f"robot_description_file:={HERE / 'mock_ur.urdf'}", *extra],
        capture_output=True, text=True, env=env, timeout=60)
    assert result.returncode == code, result.stderr
    lines = result.stderr.strip().splitlines()
    if code:
        assert "cannot start: " in lines[-1] and named in result.stderr, lines
    else:
        assert "update loop running" not in result.stderr, result.stderr


@pytest.mark.parametrize("args, named", [
    (["--check-param", "--ros-args"], "unexpected argument(s) --check-param"),   # a typo: it would have run
    (["--check-params", "-p", "update_rate:=0"], "unexpected argument(s) -p update_rate:=0"),  # no --ros-args
    (["--check-params", "--ros-args", "-p", "update_rate"], "Couldn't parse parameter override rule"),
    (["--check-params", "--ros-args", "-p", "use_sim_time:=abc"], "'use_sim_time'"),
    (["--check-params", "--ros-args", "--bogus"], "unknown ROS argument(s) ['--bogus']"),
])
def test_arguments_rcl_or_rclpy_refuse_give_one_line(args, named):
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF"}
    env.pop("ROS_LOCALHOST_ONLY", None)
    result = subprocess.run([sys.executable, "-m", "controller_manager_py.ros2_control_node", *args],
                            capture_output=True, text=True, env=env, timeout=60)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and "cannot start: " in lines[0] and named in lines[0], lines


@pytest.mark.parametrize("content, named", [
    (None, "No such file or directory"),
    (b"\x89PNG\x00", "not a UTF-8 text file"),
    (b"a: [1, 'x']\n", "Couldn't parse params file"),
])
def test_a_controller_params_file_it_cannot_use_is_one_line(tmp_path, content, named):
    controller_file = tmp_path / "controller.yaml"
    if content is not None:
        controller_file.write_bytes(content)
    params = tmp_path / "controllers.yaml"
    params.write_text(PARAMS)
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF"}
    env.pop("ROS_LOCALHOST_ONLY", None)
    result = subprocess.run(
        [sys.executable, "-m", "controller_manager_py.ros2_control_node", "--check-params", "--ros-args",
         "--params-file", str(params), "-p", f"robot_description_file:={HERE / 'mock_ur.urdf'}",
         "-p", f"joint_trajectory_controller.params_file:={controller_file}"],
        capture_output=True, text=True, env=env, timeout=60)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, lines
    assert "controller 'joint_trajectory_controller'" in lines[0] and named in lines[0], lines
