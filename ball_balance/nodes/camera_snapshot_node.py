"""`camera_snapshot`: save the running camera (/camera/image_raw) as a PNG and/or a short MP4.

    camera_snapshot --ros-args -p png:=/tmp/camera.png -p mp4:=/tmp/camera.mp4 -p duration_s:=5.0

Writes the first frame to `png`, records `duration_s` of frames (by their stamps) to `mp4`
at `fps`, then exits. For a machine without a display: look at the files instead.
"""
from __future__ import annotations

import numpy as np
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image

from ball_balance.ros.node_main import StartupError, main_for
from controller_manager_py.parameters import Param, declare_parameters

SCHEMA = [
    Param("png", "", "write the first frame here (empty: no still)", read_only=True),
    Param("mp4", "", "record a video here (empty: no video)", read_only=True),
    Param("duration_s", 5.0, "video length (by image stamps)", "s", 0.1, 3600.0, read_only=True),
    Param("fps", 30.0, "video frame rate", "Hz", 1.0, 240.0, read_only=True),
    Param("topic", "/camera/image_raw", "sensor_msgs/Image topic (bgr8 or rgb8)", read_only=True),
]


def image_to_bgr(msg: Image) -> np.ndarray:
    """sensor_msgs/Image (bgr8/rgb8) -> H x W x 3 uint8 BGR (ValueError for other encodings)."""
    if msg.encoding not in ("bgr8", "rgb8"):
        raise ValueError(f"unsupported encoding '{msg.encoding}' (bgr8 or rgb8)")
    rows = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(msg.height, msg.step)
    image = rows[:, :msg.width * 3].reshape(msg.height, msg.width, 3)
    return np.ascontiguousarray(image[:, :, ::-1] if msg.encoding == "rgb8" else image)


class CameraSnapshotNode(Node):
    def __init__(self):
        super().__init__("camera_snapshot")
        self.params = declare_parameters(self, SCHEMA)
        if not self.params["png"] and not self.params["mp4"]:
            raise StartupError("set png:=<file> and/or mp4:=<file>")
        self.writer = None
        self.first_stamp = None
        self.create_subscription(Image, self.params["topic"], self.on_image, qos_profile_sensor_data)

    def on_image(self, msg: Image) -> None:
        import cv2

        try:
            image = image_to_bgr(msg)
        except ValueError as error:
            self.get_logger().error(str(error), throttle_duration_sec=5.0)
            return
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        if self.first_stamp is None:
            self.first_stamp = stamp
            if self.params["png"]:
                cv2.imwrite(self.params["png"], image)
                self.get_logger().info(f"wrote {self.params['png']} ({msg.width}x{msg.height})")
            if self.params["mp4"]:
                self.writer = cv2.VideoWriter(self.params["mp4"], cv2.VideoWriter_fourcc(*"mp4v"),
                                              self.params["fps"], (msg.width, msg.height))
        if self.writer is not None:
            self.writer.write(image)
        if self.writer is None or stamp - self.first_stamp >= self.params["duration_s"]:
            self.finish()

    def finish(self) -> None:
        if self.writer is not None:
            self.writer.release()
            self.writer = None
            self.get_logger().info(f"wrote {self.params['mp4']}")
        raise SystemExit(0)


main = main_for(CameraSnapshotNode)
