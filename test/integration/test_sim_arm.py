"""The simulated arm over DDS: ros2_control_node hosting ball_balance/MujocoSystem with the
UR controller configuration. Commands move the arm, the camera publishes frames where all
four markers are detectable, the ball truth and drop report work, bad hardware params stop
the node with a clear line."""
import cv2
import numpy as np
import pytest
from ball_tracker_msgs.msg import BallState
from pal_statistics_msgs.msg import StatisticsNames, StatisticsValues
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Bool, Float64MultiArray
from std_srvs.srv import Trigger

from ball_balance import robot
from ball_balance.sim.config import CameraConfig, camera_intrinsics
from harness import ROOT, executable

pytestmark = pytest.mark.integration
CONTROLLERS = str(ROOT / "config" / "ur_controllers.yaml")
SIM_MANAGER = str(ROOT / "config" / "sim_manager.yaml")  # the simulated arm's scheduling, as sim_arm.sh
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


# the arm's first /joint_states after start: MuJoCo's model, the manager and its controllers
# load in a new process; 60 s ran out once at load 18 (a deadline: costs nothing when it is up)
START_TIMEOUT = 120.0


def start_sim(launcher, tmp_path, trajectory=False, ros_args=(), **params):
    urdf = tmp_path / "sim.urdf"
    params.setdefault("robot_description_file", str(urdf))
    urdf.write_text(robot.robot_description("mujoco", params))
    active = "scaled_joint_trajectory_controller" if trajectory else "forward_position_controller"
    inactive = "forward_position_controller" if trajectory else "scaled_joint_trajectory_controller"
    return launcher.start([executable("ros2_control_node"), "--ros-args", "--params-file", CONTROLLERS,
                           "--params-file", SIM_MANAGER, "-p", f"robot_description_file:={urdf}",
                           "-p", f"activate_controllers:=[joint_state_broadcaster, {active}]",
                           "-p", f"inactive_controllers:=[{inactive}]", *ros_args])


def camera_pose_from_tf(graph) -> np.ndarray:
    """T_base_camera (4x4) of camera_optical_frame from /tf_static."""
    from scipy.spatial.transform import Rotation

    from ball_balance.tf.ros import Buffer, TransformListener

    buffer = Buffer()
    TransformListener(buffer, graph.node)
    graph.spin_until(lambda: buffer.can_transform("base_link", "camera_optical_frame"), 30,
                     "base_link -> camera_optical_frame")
    tf = buffer.lookup_transform("base_link", "camera_optical_frame").transform
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat([tf.rotation.x, tf.rotation.y, tf.rotation.z, tf.rotation.w]).as_matrix()
    T[:3, 3] = [tf.translation.x, tf.translation.y, tf.translation.z]
    return T


def joint_positions(msg: JointState) -> np.ndarray:
    index = {name: i for i, name in enumerate(msg.name)}
    return np.array([msg.position[index[name]] for name in robot.JOINT_NAMES])


def test_forward_position_commands_move_the_arm_and_the_camera_sees_the_plate(launcher, graph, tmp_path):
    start_sim(launcher, tmp_path)
    (state,) = graph.collect(JointState, "/joint_states", timeout=START_TIMEOUT)
    assert np.allclose(joint_positions(state), robot.HOME_POSITIONS_RAD, atol=1e-3)

    image, = graph.collect(Image, "/camera/image_raw", qos=qos_profile_sensor_data, timeout=30)
    frames = graph.collect(Image, "/camera/image_raw", count=10, qos=qos_profile_sensor_data, timeout=30)
    stamps = [f.header.stamp.sec + f.header.stamp.nanosec * 1e-9 for f in frames]
    assert all(b > a for a, b in zip(stamps, stamps[1:], strict=False))
    info, = graph.collect(CameraInfo, "/camera/camera_info", qos=qos_profile_sensor_data, timeout=30)
    assert (image.encoding, image.width, image.height, image.step) == ("bgr8", 640, 480, 640 * 3)
    fx, fy, cx, cy = camera_intrinsics(CameraConfig())
    assert list(info.k) == pytest.approx([fx, 0, cx, 0, fy, cy, 0, 0, 1])
    pixels = np.frombuffer(bytes(image.data), dtype=np.uint8).reshape(480, 640, 3)
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50),
                                       cv2.aruco.DetectorParameters())
    _, ids, _ = detector.detectMarkers(pixels)
    assert ids is not None and sorted(ids.ravel().tolist()) == [0, 1, 2, 3]

    truth, = graph.collect(BallState, "/sim/ball_truth", qos=qos_profile_sensor_data, timeout=30)
    assert truth.header.frame_id == "plate_center" and abs(truth.x) < 0.01 and abs(truth.y) < 0.01
    assert (truth.pixel_u, truth.pixel_v) == pytest.approx((319.5, 239.5), abs=15)
    graph.collect(Clock, "/clock", qos=QoSProfile(depth=1), timeout=30)
    camera_tf = camera_pose_from_tf(graph)
    plate = robot.UrdfKinematics(robot.robot_description()).transform(
        "plate_center", "base_link", robot.joint_dict(robot.HOME_POSITIONS_RAD))
    assert np.allclose(camera_tf[:3, 3], plate[:3, 3] + [0.0, 0.0, 0.65], atol=1e-6)
    assert np.allclose(camera_tf[:3, 2], [0.0, 0.0, -1.0], atol=1e-6)  # optical z looks down

    target = np.array(robot.HOME_POSITIONS_RAD) + np.array([0.05, 0.0, 0.0, 0.02, -0.02, 0.1])
    pub = graph.node.create_publisher(Float64MultiArray, "/forward_position_controller/commands", 10)
    pub.publish(Float64MultiArray(data=target.tolist()))

    def reached(msg):
        pub.publish(Float64MultiArray(data=target.tolist()))
        return np.allclose(joint_positions(msg), target, atol=1e-3)

    graph.collect(JointState, "/joint_states", predicate=reached, timeout=30)


def test_the_manager_on_simulated_time_starts_and_stamps_with_its_own_clock(launcher, graph, tmp_path):
    # use_sim_time:=true on the node that itself publishes /clock: its start-up must not wait
    # for a clock that only ticks once it has started
    from diagnostic_msgs.msg import DiagnosticArray

    start_sim(launcher, tmp_path, camera_enabled=False, ros_args=["-p", "use_sim_time:=true"])
    graph.collect(JointState, "/joint_states", timeout=START_TIMEOUT)
    (clock,) = graph.collect(Clock, "/clock", timeout=30)
    (diagnostics,) = graph.collect(DiagnosticArray, "/diagnostics", timeout=30,
                                   predicate=lambda m: any(s.name.startswith("controller_manager") for s in m.status))
    # stamped on the simulated clock (seconds since the simulation began), not the wall clock
    assert diagnostics.header.stamp.sec < 3600 and clock.clock.sec < 3600


def test_50_rad_forward_command_keeps_the_simulated_joints_within_their_limits(launcher, graph, tmp_path):
    start_sim(launcher, tmp_path, camera_enabled=False)
    limits = robot.joint_limits(robot.robot_description())
    lower = np.array([limits[n].lower for n in robot.JOINT_NAMES])
    upper = np.array([limits[n].upper for n in robot.JOINT_NAMES])
    vmax = np.array([limits[n].velocity for n in robot.JOINT_NAMES])
    graph.collect(JointState, "/joint_states", timeout=START_TIMEOUT)
    pub = graph.node.create_publisher(Float64MultiArray, "/forward_position_controller/commands", 10)
    home = np.array(robot.HOME_POSITIONS_RAD)
    far = home.copy()
    far[[0, 2]] = 50.0   # shoulder_pan and elbow, as the fault probe did; the rest not commanded

    def within(command):
        def check(msg):
            pub.publish(Float64MultiArray(data=command.tolist()))
            index = {name: i for i, name in enumerate(msg.name)}
            q = joint_positions(msg)
            v = np.array([msg.velocity[index[name]] for name in robot.JOINT_NAMES])
            assert np.all(q >= lower) and np.all(q <= upper), f"joint positions {q} past the limits"
            assert np.all(np.abs(v) <= vmax), f"joint velocities {v} past the limits"
            return True
        return check

    # out to the limits (pan 6.28 rad away at 3 rad/s) and back, every message checked
    graph.collect(JointState, "/joint_states", predicate=lambda m: within(far)(m) and joint_positions(m)[0] > 6.2,
                  timeout=120)
    graph.collect(JointState, "/joint_states", count=200, predicate=within(far), timeout=60)
    graph.collect(JointState, "/joint_states", predicate=lambda m: within(home)(m)
                  and np.allclose(joint_positions(m), home, atol=1e-3), timeout=120)


def test_dropped_ball_is_reported_and_reset(launcher, graph, tmp_path):
    start_sim(launcher, tmp_path, camera_enabled=False, ball_x=0.15)
    reports = []
    graph.node.create_subscription(Bool, "/sim/ball_dropped", lambda m: reports.append(m.data), LATCHED)
    graph.spin_until(lambda: reports == [False], 60, "the first /sim/ball_dropped report")
    tilted = np.array(robot.HOME_POSITIONS_RAD) + np.array([0.0, 0.0, 0.0, 0.0, 0.2, 0.0])
    pub = graph.node.create_publisher(Float64MultiArray, "/forward_position_controller/commands", 10)

    def dropped():
        pub.publish(Float64MultiArray(data=tilted.tolist()))
        return reports[-1]

    graph.spin_until(dropped, 30, "the ball to drop off the tilted plate")
    pub.publish(Float64MultiArray(data=list(robot.HOME_POSITIONS_RAD)))
    response = graph.call(Trigger, "/sim/reset_ball", Trigger.Request())
    assert response.success
    graph.spin_until(lambda: reports[-1] is False, 30, "the drop report to clear after the reset")


def test_trajectory_moves_the_arm(launcher, graph, tmp_path):
    pytest.importorskip("controller_manager_py.controllers.joint_trajectory")
    from builtin_interfaces.msg import Duration
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    start_sim(launcher, tmp_path, trajectory=True, camera_enabled=False)
    graph.collect(JointState, "/joint_states", timeout=START_TIMEOUT)
    target = np.array(robot.HOME_POSITIONS_RAD) + np.array([0.0, 0.0, 0.0, -0.05, 0.05, 0.0])
    traj = JointTrajectory(joint_names=list(robot.JOINT_NAMES),
                           points=[JointTrajectoryPoint(positions=target.tolist(),
                                                        time_from_start=Duration(sec=0, nanosec=200_000_000))])
    pub = graph.node.create_publisher(JointTrajectory, "/scaled_joint_trajectory_controller/joint_trajectory", 10)
    graph.wait_for_topic("/scaled_joint_trajectory_controller/joint_trajectory")

    def reached(msg):
        if not reached.sent:
            pub.publish(traj)
            reached.sent = True
        return np.allclose(joint_positions(msg), target, atol=2e-3)

    reached.sent = False
    graph.collect(JointState, "/joint_states", predicate=reached, timeout=30)


def test_pause_step_reset_and_push_services(launcher, graph, tmp_path):
    from geometry_msgs.msg import Vector3, Vector3Stamped, WrenchStamped
    from std_srvs.srv import SetBool

    sim = start_sim(launcher, tmp_path, camera_enabled=False, step_simulation_steps=10)
    clocks = []
    graph.node.create_subscription(Clock, "/clock", lambda m: clocks.append(m.clock.sec + m.clock.nanosec * 1e-9),
                                   QoSProfile(depth=10))
    truths, pushed = [], []
    graph.node.create_subscription(BallState, "/sim/ball_truth", truths.append, qos_profile_sensor_data)
    graph.node.create_subscription(Vector3Stamped, "/sim/ball_pushed", pushed.append, 10)
    graph.spin_until(lambda: len(clocks) > 0, 60, "/clock")
    assert not graph.call(Trigger, "/sim/step_simulation", Trigger.Request()).success  # not paused
    # the reply comes once the loop has paused: nothing moves time from here but the steps
    paused = graph.call(SetBool, "/sim/set_pause", SetBool.Request(data=True))
    assert paused.success and paused.message.startswith("simulation paused from t="), paused.message
    paused_s = float(paused.message.rsplit("t=", 1)[1].split()[0])

    def step() -> tuple:
        response = graph.call(Trigger, "/sim/step_simulation", Trigger.Request())
        assert response.success and response.message.startswith("advanced 10 physics step"), response.message
        start, end = (float(t) for t in response.message.rsplit("t=", 1)[1].split()[0:3:2])
        # /clock ticks every 10 ms of sim time (clock_rate_hz 100): the 10 ms step shows in one tick
        graph.spin_until(lambda: clocks[-1] >= start + 0.008 - 1e-6, 30, "the clock to follow the step")
        return start, end

    spans = [step() for _ in range(3)]
    assert spans[0][0] == pytest.approx(paused_s, abs=1e-9)
    assert all(end - start == pytest.approx(0.010, abs=1e-6) for start, end in spans)
    assert all(next_start == pytest.approx(end, abs=1e-9) for (_, end), (next_start, _) in zip(spans, spans[1:]))
    second = spans[-1][1]
    assert graph.call(SetBool, "/sim/set_pause", SetBool.Request(data=False)).success
    graph.spin_until(lambda: clocks[-1] > second + 0.1, 30, "the clock to run again")

    pub = graph.node.create_publisher(Vector3Stamped, "/sim/push_ball", 10)
    graph.wait_for_topic("/sim/push_ball")
    # bad pushes and wrenches (absurd, not finite, an unknown frame) are refused, counted and said
    # once per topic while they keep coming; none reaches the ball (the first push applied is
    # the good one below)
    wrench_pub = graph.node.create_publisher(WrenchStamped, "/sim/ball_wrench", 10)
    graph.wait_for_topic("/sim/ball_wrench")
    bad_pushes = [Vector3Stamped(vector=Vector3(x=1.0e4, z=1.0e4)), Vector3Stamped(vector=Vector3(x=float("nan"))),
                  Vector3Stamped(vector=Vector3(x=0.1))]
    bad_pushes[2].header.frame_id = "camera"
    bad_wrenches = [WrenchStamped(), WrenchStamped()]
    bad_wrenches[0].wrench.force.x, bad_wrenches[1].wrench.torque.z = 1.0e4, float("inf")
    for _ in range(40):
        for msg in bad_pushes:
            pub.publish(msg)
        for msg in bad_wrenches:
            wrench_pub.publish(msg)
        graph.spin_for(0.005)
    graph.spin_until(lambda: "/sim/push_ball: velocity (10000.0" in sim.output()
                     and "/sim/ball_wrench: wrench (10000.0" in sim.output(), 10, "the refusals said")
    graph.spin_for(0.5)
    assert sim.output().count("/sim/push_ball: ") <= 2 and sim.output().count("/sim/ball_wrench: ") <= 2
    assert not pushed
    # ... and counted in the manager's introspection
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    (names,) = graph.collect(StatisticsNames, "/controller_manager/introspection_data/names", qos=latched)
    (refused,) = [i for i, name in enumerate(names.names) if name.endswith(".disturbances_refused")]

    def counted():
        (values,) = graph.collect(StatisticsValues, "/controller_manager/introspection_data/values")
        # (each one that arrived: a loaded machine may drop some of the 200 from the topic's queue)
        return values.names_version == names.names_version and 0 < values.values[refused] <= 40 * 5

    graph.spin_until(counted, 30, "the refusals in the introspection")
    push = Vector3Stamped()
    push.header.frame_id = "plate_center"
    push.vector.x = 0.1

    def rolling():
        if not truths or abs(truths[-1].vx) < 0.05:
            pub.publish(push)
            return False
        return True

    graph.spin_until(rolling, 30, "the pushed ball to roll")
    # every push applied is announced, with the simulated time it acted and its velocity change
    graph.spin_until(lambda: pushed, 30, "the push on /sim/ball_pushed")
    assert pushed[0].vector.x == pytest.approx(0.1) and pushed[0].header.frame_id == "plate_center"
    assert pushed[0].header.stamp.sec + pushed[0].header.stamp.nanosec * 1e-9 > second
    assert graph.call(Trigger, "/sim/reset_world", Trigger.Request()).success
    graph.spin_until(lambda: abs(truths[-1].vx) < 0.01 and abs(truths[-1].x) < 0.005, 30,
                     "the ball at rest at the centre after reset_world")


@pytest.mark.parametrize("params,message", [({"camera_width": 0}, "camera_width"),
                                            ({"domain": "moon"}, "unknown domain")])
def test_bad_hardware_parameter_stops_the_node_with_a_clear_error(launcher, tmp_path, params, message):
    process = start_sim(launcher, tmp_path, **params)
    assert process.wait(60) != 0
    assert message in process.output()


def test_sim_arm_script_runs_the_graph_refuses_a_second_and_ctrl_c_stops_everything(launcher, graph, tmp_path):
    import os
    import signal

    script = launcher.start(["bash", str(ROOT / "scripts" / "sim_arm.sh")])
    graph.collect(JointState, "/joint_states", timeout=START_TIMEOUT)
    graph.wait_for_topic("/tf_static")
    graph.wait_for_topic("/forward_position_controller/commands")
    # a second graph on the same ROS domain is refused with one line, and this one runs on
    second = launcher.run(["bash", str(ROOT / "scripts" / "sim_arm.sh")], timeout=120)
    assert second.returncode == 2, second.stderr[-2000:]
    # the running graph's lock on its domain, whatever discovery would see in its 3 s
    assert f"ROS_DOMAIN_ID={launcher.domain_id} is taken: a simulation on this machine runs on it " \
           f"(sim_arm.sh pid {script.popen.pid}" in second.stderr, second.stderr
    assert script.popen.poll() is None
    os.kill(script.popen.pid, signal.SIGINT)  # the script only: its trap must stop the rest
    assert script.wait(30) is not None
    graph.spin_until(lambda: graph.node.count_publishers("/joint_states") == 0
                     and graph.node.count_publishers("/tf_static") == 0, 30, "the nodes to exit")
    # what the nodes say as they stop goes out while ROS can still carry it, or to stderr
    assert "Failed to publish log message" not in script.output(), script.output()[-2000:]


def test_sim_arm_script_refuses_a_domain_where_discovery_finds_a_clock(launcher, graph):
    from rosgraph_msgs.msg import Clock

    graph.node.create_publisher(Clock, "/clock", 10)  # as a bag played with --clock
    result = launcher.run(["bash", str(ROOT / "scripts" / "sim_arm.sh"), "--check-params"], timeout=120)
    assert result.returncode == 2, result.stderr[-2000:]
    assert f"ROS_DOMAIN_ID={launcher.domain_id} is taken: /clock has 1 publisher(s)" in result.stderr, result.stderr


def test_camera_snapshot_writes_a_png_of_the_running_camera(launcher, graph, tmp_path):
    start_sim(launcher, tmp_path, camera_width=320, camera_height=240)
    png = tmp_path / "camera.png"
    snapshot = launcher.start([executable("camera_snapshot"), "--ros-args", "-p", f"png:={png}"])
    assert snapshot.wait(60) == 0
    assert cv2.imread(str(png)).shape == (240, 320, 3)


def test_sim_arm_script_refuses_bad_parameters_before_starting_anything(launcher):
    result = launcher.run(["bash", str(ROOT / "scripts" / "sim_arm.sh"), "--param", "camera_width=0"], timeout=60)
    assert result.returncode == 2
    assert "camera_width" in result.stderr and "Traceback" not in result.stderr
