"""robot_state_publisher over DDS: /robot_description latched, /tf from /joint_states with
their stamps, base_link -> plate_center agreeing with the MuJoCo world's plate pose."""
import math

import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from ball_balance import robot
from ball_balance.sim.world import SimWorld
from ball_balance.tf.ros import Buffer, TransformListener
from harness import executable

pytestmark = pytest.mark.integration
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def quat_angle(a, b):
    dot = abs(sum(x * y for x, y in zip(a, b, strict=True)))
    return 2.0 * math.acos(min(1.0, dot))


def test_tf_plate_center_matches_the_mujoco_plate(launcher, graph):
    launcher.start([executable("robot_state_publisher")])
    (description,) = graph.collect(String, "/robot_description", qos=LATCHED, timeout=30)
    assert robot.hardware_plugin(description.data) == "ball_balance/MujocoSystem"

    q = np.array(robot.HOME_POSITIONS_RAD) + np.array([0.2, 0.1, -0.15, 0.12, -0.08, 0.5])
    buffer = Buffer()
    TransformListener(buffer, graph.node)
    pub = graph.node.create_publisher(JointState, "/joint_states", 10)
    msg = JointState(name=list(robot.JOINT_NAMES), position=q.tolist())
    msg.header.stamp.sec, msg.header.stamp.nanosec = 12, 500_000_000

    def published_and_known():
        pub.publish(msg)
        return buffer.can_transform("base_link", "plate_center", msg.header.stamp)

    graph.spin_until(published_and_known, 30, "base_link -> plate_center on /tf")
    tf = buffer.lookup_transform("base_link", "plate_center", msg.header.stamp)
    assert (tf.header.stamp.sec, tf.header.stamp.nanosec) == (12, 500_000_000)

    world = SimWorld()
    world.set_joint_positions(q)
    p_W, R_WP = world.plate_pose()
    t = tf.transform.translation
    assert np.allclose([t.x, t.y, t.z], p_W, atol=1e-4)
    from scipy.spatial.transform import Rotation

    r = tf.transform.rotation
    assert quat_angle([r.x, r.y, r.z, r.w], Rotation.from_matrix(R_WP).as_quat()) < 1e-3


def test_bad_description_file_stops_with_one_clear_line(launcher, tmp_path):
    result = launcher.run([executable("robot_state_publisher"), "--ros-args", "-p",
                           f"robot_description_file:={tmp_path}/missing.urdf"], timeout=60)
    assert result.returncode != 0
    assert "robot_description_file" in result.stderr and "Traceback" not in result.stderr


def test_non_finite_joint_position_is_skipped_and_the_rest_published(launcher, graph):
    from tf2_msgs.msg import TFMessage

    process = launcher.start([executable("robot_state_publisher")])
    graph.wait_for_topic("/tf")
    pub = graph.node.create_publisher(JointState, "/joint_states", 10)
    q = list(robot.HOME_POSITIONS_RAD)
    q[5] = math.nan
    msg = JointState(name=list(robot.JOINT_NAMES), position=q)

    def has_arm(tf):
        pub.publish(msg)
        return bool(tf.transforms)

    sub_msgs = []
    graph.node.create_subscription(TFMessage, "/tf", sub_msgs.append, 100)
    graph.spin_until(lambda: has_arm(TFMessage(transforms=[t for m in sub_msgs for t in m.transforms])), 30,
                     "/tf from a joint state with one NaN")
    children = {t.child_frame_id for m in sub_msgs for t in m.transforms}
    assert "shoulder_link" in children and "wrist_3_link" not in children
    assert process.running
