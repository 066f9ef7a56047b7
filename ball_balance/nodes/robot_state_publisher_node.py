"""`robot_state_publisher`: URDF + /joint_states -> /tf, /tf_static, /robot_description.

Our substitute for ros/robot_state_publisher (yourdfpy parses the URDF; the joint
transforms are ball_balance.robot.UrdfKinematics):
- /robot_description (std_msgs/String, reliable, transient local): the URDF text, from the
  `robot_description` parameter, else the file `robot_description_file`, else
  config/ur5e_ball_balance.urdf (MuJoCo hardware selected);
- /tf_static: every fixed joint once (transient local, as tf2's static broadcaster);
- /tf: every moving joint named in a /joint_states message, stamped with that message's
  stamp (reliable, depth 100). Non-finite positions are skipped and counted (throttled log).
`frame_prefix` is prepended to every frame id, as upstream.
"""
from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import TransformStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from ball_balance import robot
from ball_balance.tf.ros import StaticTransformBroadcaster, TransformBroadcaster, transform_to_msg
from ball_balance.tf.transform import Transform, quat_multiply
from controller_manager_py.parameters import Param, declare_parameters
from controller_manager_py.ros.node_main import StartupError, main_for
from controller_manager_py.text_files import TextFileError, read_text_file

SCHEMA = [
    Param("robot_description", "", "URDF text (empty: read robot_description_file)", read_only=True, user_facing=True),
    Param("robot_description_file", "", "URDF file (empty: config/ur5e_ball_balance.urdf)", read_only=True,
          user_facing=True),
    Param("frame_prefix", "", "prefix for every published frame id", read_only=True, user_facing=True),
]
DESCRIPTION_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)


def matrix_to_transform(T: np.ndarray) -> Transform:
    """4x4 homogeneous matrix -> Transform (translation, quaternion x y z w)."""
    return Transform.from_values(tuple(T[:3, 3]), tuple(Rotation.from_matrix(T[:3, :3]).as_quat()))


class RobotStatePublisherNode(Node):
    def __init__(self):
        super().__init__("robot_state_publisher")
        self.params = declare_parameters(self, SCHEMA)
        text = self._load_description()
        try:
            self.kinematics = robot.UrdfKinematics(text)
        except robot.RobotDescriptionError as error:
            raise StartupError(f"robot_description: {error}") from None
        self.prefix = self.params["frame_prefix"]
        self.moving = set(self.kinematics.moving_joints)
        self.rejected = 0
        self.description_pub = self.create_publisher(String, "/robot_description", DESCRIPTION_QOS)
        self.description_pub.publish(String(data=text))
        self.static_broadcaster = StaticTransformBroadcaster(self)
        now = self.get_clock().now().to_msg()
        static = [transform_to_msg(matrix_to_transform(T), self.prefix + parent, self.prefix + child, now)
                  for parent, child, T in self.kinematics.fixed_transforms()]
        if static:
            self.static_broadcaster.send_transform(static)
        self.fixed_joints = len(static)
        # per moving joint: (parent, child, origin translation, origin quaternion, unit axis, kind),
        # so a joint state costs one quaternion product per joint
        self.joints = {}
        for name in self.moving:
            kind, parent, child, origin, axis = self.kinematics.joint(name)
            self.joints[name] = (self.prefix + parent, self.prefix + child, origin[:3, 3].copy(),
                                 matrix_to_transform(origin).rotation, axis / np.linalg.norm(axis), kind)
        self.broadcaster = TransformBroadcaster(self)
        self.create_subscription(JointState, "/joint_states", self.on_joint_states, 10)

    def announce(self) -> None:
        """The start-up line (controller_manager_py.ros.node_main.run_node)."""
        self.get_logger().info(f"robot '{self.kinematics.robot_name}': {self.fixed_joints} fixed, "
                               f"{len(self.moving)} moving joints")

    def _load_description(self) -> str:
        text = self.params["robot_description"]
        if text:
            return text
        path = self.params["robot_description_file"]
        try:
            return read_text_file(path or robot.robot_description_path(), "robot description")
        except (TextFileError, robot.RobotDescriptionError) as error:
            raise StartupError(f"robot_description_file: {error}") from None

    def on_joint_states(self, msg: JointState) -> None:
        transforms = []
        for name, position in zip(msg.name, msg.position, strict=False):
            if name not in self.moving:
                continue
            if not math.isfinite(position):
                self.rejected += 1
                self.get_logger().warn(f"non-finite position for '{name}' skipped ({self.rejected} so far)",
                                       throttle_duration_sec=5.0)
                continue
            transforms.append(self.joint_msg(name, position, msg.header.stamp))
        if transforms:
            try:
                self.broadcaster.send_transform(transforms)
            except Exception:  # noqa: BLE001 - rclpy raises RCLError once SIGTERM shut the context
                if self.context.ok():
                    raise

    def joint_msg(self, name: str, position: float, stamp) -> TransformStamped:
        """T_parent_child of a moving joint: origin, then the joint's motion about/along its axis."""
        parent, child, t_origin, q_origin, axis, kind = self.joints[name]
        msg = TransformStamped()
        msg.header.frame_id, msg.header.stamp, msg.child_frame_id = parent, stamp, child
        tr, rot = msg.transform.translation, msg.transform.rotation
        if kind == "prismatic":
            q_motion = (0.0, 0.0, 0.0, 1.0)
            tr.x, tr.y, tr.z = t_origin + rotation_about_quat(q_origin, axis * position)
        else:
            half = 0.5 * position
            s = math.sin(half)
            q_motion = (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(half))
            tr.x, tr.y, tr.z = t_origin
        rot.x, rot.y, rot.z, rot.w = quat_multiply(q_origin, q_motion)
        return msg


def rotation_about_quat(q, v) -> np.ndarray:
    """Rotate vector v by the unit quaternion q (x, y, z, w)."""
    return Rotation.from_quat(q).apply(v)


main = main_for(RobotStatePublisherNode)
