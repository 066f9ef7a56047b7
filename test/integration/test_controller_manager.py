"""ros2_control_node as a real process over DDS: services, topics, switching, spawner."""
import math
import os
import signal
import time
from pathlib import Path

import pytest
from builtin_interfaces.msg import Duration
from control_msgs.msg import JointTrajectoryControllerState
from controller_manager_msgs.msg import ControllerManagerActivity
from controller_manager_msgs.srv import (
    ListControllers,
    ListControllerTypes,
    ListHardwareComponents,
    ListHardwareInterfaces,
    SetHardwareComponentState,
    SwitchController,
)
from diagnostic_msgs.msg import DiagnosticArray
from pal_statistics_msgs.msg import StatisticsNames, StatisticsValues
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from harness import ROOT, executable

pytestmark = pytest.mark.integration
URDF = ROOT / "config" / "mock_ur.urdf"
CONTROLLERS = ROOT / "config" / "ur_controllers.yaml"
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
TARGET = [0.1, -1.4, 1.4, -1.5, 1.5, 0.2]
JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
          "wrist_3_joint"]


def start_manager(launcher, *params: str, urdf: Path = URDF):
    args = [executable("ros2_control_node"), "--ros-args", "--params-file", str(CONTROLLERS)]
    if urdf is not None:
        args += ["-p", f"robot_description_file:={urdf}"]
    for p in params:
        args += ["-p", p]
    return launcher.start(args, name="ros2_control_node")


def controllers(graph):
    response = graph.call(ListControllers, "/controller_manager/list_controllers", ListControllers.Request())
    return {c.name: c for c in response.controller}


def switch(graph, activate=(), deactivate=(), strictness=SwitchController.Request.STRICT):
    request = SwitchController.Request(activate_controllers=list(activate), deactivate_controllers=list(deactivate),
                                       strictness=strictness)
    request.timeout.sec = 2
    return graph.call(SwitchController, "/controller_manager/switch_controller", request).ok


def test_services_commands_switching_and_numbers_over_dds(launcher, graph):
    node = start_manager(launcher)
    graph.wait_for_service("/controller_manager/list_controllers", timeout=30)
    graph.spin_until(lambda: len(controllers(graph)) == 3, 45, "the configured controllers")  # spawned at start
    listed = controllers(graph)
    assert listed["joint_state_broadcaster"].state == "active"
    assert listed["forward_position_controller"].state == "active"
    assert listed["forward_position_controller"].update_rate == 500
    assert sorted(listed["forward_position_controller"].claimed_interfaces) == sorted(f"{j}/position" for j in JOINTS)
    assert listed["scaled_joint_trajectory_controller"].state == "inactive", node.output()

    # commands on /forward_position_controller/commands show up on /joint_states (mock mirrors them)
    publisher = graph.node.create_publisher(Float64MultiArray, "/forward_position_controller/commands", 10)
    graph.wait_for_topic("/joint_states")

    def arrived(msg):
        publisher.publish(Float64MultiArray(data=TARGET))
        return all(math.isclose(a, b, abs_tol=1e-9) for a, b in zip(msg.position, TARGET))
    graph.collect(JointState, "/joint_states", predicate=arrived, timeout=10)
    publisher.publish(Float64MultiArray(data=[1.0, 2.0]))  # wrong length: refused, nothing moves
    publisher.publish(Float64MultiArray(data=[math.nan] + TARGET[1:]))  # non-finite: refused
    later = graph.collect(JointState, "/joint_states", count=100)  # ~0.2 s: the commands have arrived
    assert all(list(m.position) == pytest.approx(TARGET) for m in later)

    # claiming conflict (STRICT) changes nothing; a swap in one switch works
    assert not switch(graph, activate=["scaled_joint_trajectory_controller"])
    assert controllers(graph)["forward_position_controller"].state == "active"
    assert switch(graph, activate=["scaled_joint_trajectory_controller"], deactivate=["forward_position_controller"])
    listed = controllers(graph)
    assert listed["scaled_joint_trajectory_controller"].state == "active"
    assert listed["forward_position_controller"].state == "inactive"
    # ~/activity follows the change (the manager is told, it does not poll)
    graph.collect(ControllerManagerActivity, "/controller_manager/activity", qos=LATCHED, timeout=10,
                  predicate=lambda m: {c.name: c.state.label for c in m.controllers}.get(
                      "scaled_joint_trajectory_controller") == "active")
    # its state timer, stopped while it was inactive, runs again
    graph.collect(JointTrajectoryControllerState, "/scaled_joint_trajectory_controller/controller_state", timeout=10)

    # the trajectory controller takes over from where the arm is and reaches the waypoint
    goal = [0.0, -1.5, 1.5, -1.5, 1.5, 0.0]
    trajectory = JointTrajectory(joint_names=list(JOINTS))
    trajectory.points.append(JointTrajectoryPoint(positions=goal, time_from_start=Duration(nanosec=300_000_000)))
    trajectories = graph.node.create_publisher(JointTrajectory, "/scaled_joint_trajectory_controller/joint_trajectory",
                                               10)
    graph.spin_until(lambda: trajectories.get_subscription_count() > 0, 10, "the trajectory subscription")
    trajectories.publish(trajectory)
    graph.collect(JointState, "/joint_states", timeout=10,
                  predicate=lambda m: list(m.position) == pytest.approx(goal, abs=1e-9))
    bad = JointTrajectory(joint_names=list(JOINTS[:5]) + ["knee_joint"])  # unknown joint: refused
    bad.points.append(JointTrajectoryPoint(positions=TARGET, time_from_start=Duration(nanosec=100_000_000)))
    trajectories.publish(bad)
    later = graph.collect(JointState, "/joint_states", count=100)
    assert all(list(m.position) == pytest.approx(goal, abs=1e-9) for m in later)
    assert switch(graph, activate=["ghost", "forward_position_controller"],
                  deactivate=["scaled_joint_trajectory_controller"], strictness=SwitchController.Request.BEST_EFFORT)

    # hardware listings
    hw = graph.call(ListHardwareComponents, "/controller_manager/list_hardware_components",
                    ListHardwareComponents.Request()).component
    assert [(c.name, c.plugin_name, c.state.label) for c in hw] == [("mock_ur", "mock_components/GenericSystem",
                                                                     "active")]
    interfaces = graph.call(ListHardwareInterfaces, "/controller_manager/list_hardware_interfaces",
                            ListHardwareInterfaces.Request())
    claimed = {i.name for i in interfaces.command_interfaces if i.is_claimed}
    assert "elbow_joint/position" in claimed
    assert "speed_scaling/speed_scaling_factor" in {i.name for i in interfaces.state_interfaces}
    types = graph.call(ListControllerTypes, "/controller_manager/list_controller_types",
                       ListControllerTypes.Request()).types
    assert "joint_trajectory_controller/JointTrajectoryController" in types

    # statistics: names (latched) then values with the same names_version
    (names,) = graph.collect(StatisticsNames, "/controller_manager/statistics/names", qos=LATCHED)
    assert "joint_state_broadcaster.stats/execution_time/average" in names.names
    assert "mock_ur.stats/read_cycle/periodicity/average" in names.names
    (values,) = graph.collect(StatisticsValues, "/controller_manager/statistics/values")
    assert values.names_version == names.names_version and len(values.values) == len(names.names)
    value = dict(zip(names.names, values.values))
    assert value["controller_manager.total_time"] > 0  # ros2_control Jazzy's name
    assert value["controller_manager.stats/execution_time/sample_count"] > 0
    assert value["joint_state_broadcaster.stats/execution_time/sample_count"] > 0
    assert math.isfinite(value["controller_manager.stats/periodicity/average"])
    (intro,) = graph.collect(StatisticsNames, "/controller_manager/introspection_data/names", qos=LATCHED)
    assert "state_interface.elbow_joint/position" in intro.names
    assert "command_interface.elbow_joint/position.is_limited" in intro.names

    (diag,) = graph.collect(DiagnosticArray, "/diagnostics", timeout=10)
    assert [s.name for s in diag.status] == ["controller_manager: Controllers Activity",
                                             "controller_manager: Hardware Components Activity",
                                             "controller_manager: Controller Manager Activity"]
    (activity,) = graph.collect(ControllerManagerActivity, "/controller_manager/activity", qos=LATCHED)
    assert {c.name: c.state.label for c in activity.controllers}["forward_position_controller"] == "active"


def test_description_from_topic_and_the_spawner(launcher, graph, tmp_path):
    launcher_env_params = ["activate_controllers:=[joint_state_broadcaster]"]
    start_manager(launcher, *launcher_env_params, urdf=None)
    publisher = graph.node.create_publisher(String, "/robot_description", LATCHED)
    publisher.publish(String(data=URDF.read_text()))
    graph.wait_for_service("/controller_manager/list_controllers", timeout=30)
    graph.spin_until(lambda: "joint_state_broadcaster" in controllers(graph), 45, "controllers spawned")
    env_run = launcher.run([executable("spawner"), "scaled_joint_trajectory_controller", "--inactive"], timeout=30)
    assert env_run.returncode == 0, env_run.stderr
    run = launcher.run([executable("spawner"), "forward_position_controller"], timeout=30)
    assert run.returncode == 0, run.stderr
    listed = controllers(graph)
    assert listed["forward_position_controller"].state == "active"
    assert listed["scaled_joint_trajectory_controller"].state == "inactive"
    run = launcher.run([executable("spawner"), "extra_jsb", "-t", "joint_state_broadcaster/JointStateBroadcaster",
                        "--inactive"], timeout=30)
    assert run.returncode == 0, run.stderr
    assert controllers(graph)["extra_jsb"].state == "inactive"
    params = tmp_path / "fwd2.yaml"
    params.write_text("fwd2:\n  ros__parameters:\n    joints: [elbow_joint]\n")
    run = launcher.run([executable("spawner"), "fwd2", "-t", "position_controllers/JointGroupPositionController",
                        "-p", str(params), "--inactive"], timeout=30)
    assert run.returncode == 0, run.stderr
    assert list(controllers(graph)["fwd2"].required_command_interfaces) == ["elbow_joint/position"]
    # --unload-on-kill: the controller lives as long as the spawner
    spawner = launcher.start([executable("spawner"), "jsb_tmp", "-t", "joint_state_broadcaster/JointStateBroadcaster",
                              "--unload-on-kill"], name="spawner_u")
    graph.spin_until(lambda: getattr(controllers(graph).get("jsb_tmp"), "state", "") == "active", 60, "jsb_tmp")
    os.killpg(spawner.popen.pid, signal.SIGINT)
    assert spawner.wait(timeout=30) == 0, spawner.output()
    assert "jsb_tmp" not in controllers(graph)
    # Ctrl-C while it is still spawning (loaded, perhaps not yet active) unloads as well
    spawner = launcher.start([executable("spawner"), "jsb_tmp2", "-t", "joint_state_broadcaster/JointStateBroadcaster",
                              "--unload-on-kill"], name="spawner_u2")
    graph.spin_until(lambda: "jsb_tmp2" in controllers(graph), 60, "jsb_tmp2 loaded")
    os.killpg(spawner.popen.pid, signal.SIGINT)
    assert spawner.wait(timeout=30) == 0, spawner.output()
    assert "jsb_tmp2" not in controllers(graph)
    # ... at any instant of configuring and activating: a signal inside a service call is no SystemError
    for delay_s in (0.0, 0.05, 0.15, 0.3):
        spawner = launcher.start([executable("spawner"), "jsb_tmp3", "-t",
                                  "joint_state_broadcaster/JointStateBroadcaster", "--unload-on-kill"],
                                 name=f"spawner_u3_{delay_s}")
        graph.spin_until(lambda: "jsb_tmp3" in controllers(graph), 60, "jsb_tmp3 loaded")
        time.sleep(delay_s)
        os.killpg(spawner.popen.pid, signal.SIGINT)
        assert spawner.wait(timeout=30) == 0, spawner.output()
        assert "jsb_tmp3" not in controllers(graph)
    run = launcher.run([executable("spawner"), "nonexistent_controller"], timeout=30)
    assert run.returncode == 1 and "failed loading controller 'nonexistent_controller'" in run.stderr

    # hardware to inactive: the controllers commanding it are deactivated first
    request = SetHardwareComponentState.Request(name="mock_ur")
    request.target_state.id, request.target_state.label = 2, "inactive"
    response = graph.call(SetHardwareComponentState, "/controller_manager/set_hardware_component_state", request)
    assert response.ok and response.state.label == "inactive"
    listed = controllers(graph)
    assert listed["forward_position_controller"].state == "inactive"
    assert listed["joint_state_broadcaster"].state == "active"  # states are still read


def test_malformed_description_stops_with_one_clear_line(launcher, tmp_path):
    broken = tmp_path / "broken.urdf"
    broken.write_text(URDF.read_text().replace("mock_components/GenericSystem", "acme/Robot"))
    process = start_manager(launcher, urdf=broken)
    assert process.wait(timeout=30) == 2
    lines = [line for line in process.output().splitlines() if line.strip()]
    assert any("unknown hardware plugin 'acme/Robot'" in line for line in lines), lines


def _without_limit(joint: str) -> str:
    text = URDF.read_text()
    start = text.index(f'<joint name="{joint}" type="revolute">')
    limit_start = text.index("<limit", start)
    return text[:limit_start] + text[text.index("/>", limit_start) + 2:]


def test_joint_without_limit_is_refused_at_start_with_one_line_unless_allowed(launcher, graph, tmp_path):
    unlimited = tmp_path / "unlimited.urdf"
    unlimited.write_text(_without_limit("elbow_joint"))
    process = start_manager(launcher, urdf=unlimited)
    assert process.wait(timeout=30) == 2
    (line,) = [line for line in process.output().splitlines() if "no <limit>" in line]
    assert "elbow_joint" in line and "allow_joints_without_limits" in line
    allowed = start_manager(launcher, "allow_joints_without_limits:=true", urdf=unlimited)
    graph.wait_for_service("/controller_manager/list_controllers", timeout=30)
    assert allowed.running


def test_forward_command_at_50_rad_is_limited_counted_in_diagnostics(launcher, graph):
    start_manager(launcher, "diagnostics.period:=0.5")
    graph.wait_for_service("/controller_manager/list_controllers", timeout=30)
    graph.spin_until(lambda: controllers(graph).get("forward_position_controller") is not None
                     and controllers(graph)["forward_position_controller"].state == "active", 20, "forward controller")
    publisher = graph.node.create_publisher(Float64MultiArray, "/forward_position_controller/commands", 10)
    graph.wait_for_topic("/forward_position_controller/commands")
    command = [0.0, -1.5707963267948966, 50.0, -1.5707963267948966, 1.5707963267948966, 0.0]
    elbow = []

    def at_limit():
        publisher.publish(Float64MultiArray(data=command))
        states = graph.collect(JointState, "/joint_states", timeout=10)
        elbow.append(dict(zip(states[0].name, states[0].position))["elbow_joint"])
        return abs(elbow[-1] - math.pi) < 1e-6
    graph.spin_until(at_limit, 30, "the elbow at its URDF limit")
    assert max(elbow) <= math.pi + 1e-9

    def warned():
        (diag,) = graph.collect(DiagnosticArray, "/diagnostics", timeout=10)
        hardware = [s for s in diag.status if s.name.endswith("Hardware Components Activity")]
        # at least WARN: on a loaded machine the read/write periodicity may make it ERROR as well
        return hardware and hardware[0].level in (b"\x01", b"\x02") and "mock_ur" in hardware[0].message \
            and "limited commands" in hardware[0].message
    publisher.publish(Float64MultiArray(data=command))
    graph.spin_until(warned, 20, "a WARN naming the limited commands on /diagnostics")


@pytest.mark.parametrize("interrupts", [1, 2])
def test_ctrl_c_stops_the_manager_without_errors(launcher, graph, interrupts):
    process = start_manager(launcher)
    graph.collect(JointState, "/joint_states", count=5, timeout=30)  # the loop is publishing
    for _ in range(interrupts):
        os.kill(process.popen.pid, signal.SIGINT)
    code = process.wait(timeout=30)
    output = process.output()
    assert "Traceback" not in output and "RCLError" not in output and "context is invalid" not in output, output
    assert code in (0, -signal.SIGINT), output  # a second Ctrl-C at the very end may end it by the signal
