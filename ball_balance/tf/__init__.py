"""TF in pure Python (tf2_ros is not on PyPI).

Pure part (no rclpy; import from here):
    Transform, BufferCore, quat_from_euler, quat_to_euler, slerp,
    TransformException, LookupException, ConnectivityException, ExtrapolationException.
ROS part (rclpy; import from ball_balance.tf.ros):
    Buffer, TransformListener, TransformBroadcaster, StaticTransformBroadcaster.
"""
from ball_balance.tf.buffer import (
    BufferCore,
    ConnectivityException,
    ExtrapolationException,
    LookupException,
    TransformException,
)
from ball_balance.tf.transform import Transform, quat_from_euler, quat_to_euler, slerp

__all__ = [
    "BufferCore", "ConnectivityException", "ExtrapolationException", "LookupException",
    "TransformException", "Transform", "quat_from_euler", "quat_to_euler", "slerp",
]
