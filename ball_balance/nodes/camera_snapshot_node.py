"""`camera_snapshot`: save the running camera (/camera/image_raw) as a PNG and/or a short MP4.

    camera_snapshot --ros-args -p png:=/tmp/camera.png -p mp4:=/tmp/camera.mp4 -p duration_s:=5.0

Writes the first frame to `png`, records `duration_s` of frames (by their stamps) to `mp4`
at `fps`, then exits. For a machine without a display: look at the files instead.
"""
from __future__ import annotations

import os

from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image

from ball_balance.ros.images import decode_image
from controller_manager_py.parameters import Param, declare_parameters
from controller_manager_py.ros.node_main import StartupError, main_for


def _in_a_folder(path: str):
    folder = os.path.dirname(os.path.abspath(path))
    return None if not path or os.path.isdir(folder) else f"names a folder that does not exist ({folder})"


SCHEMA = [
    Param("png", "", "write the first frame here (empty: no still)", read_only=True, user_facing=True,
          check=_in_a_folder),
    Param("mp4", "", "record a video here (empty: no video)", read_only=True, user_facing=True, check=_in_a_folder),
    Param("duration_s", 5.0, "video length (by image stamps)", "s", 0.1, 3600.0, read_only=True, user_facing=True),
    Param("fps", 30.0, "video frame rate", "Hz", 1.0, 240.0, read_only=True, user_facing=True),
    Param("topic", "/camera/image_raw", "sensor_msgs/Image topic (bgr8 or rgb8)", read_only=True, user_facing=True),
]


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

        image, problem = decode_image(msg)
        if image is None:
            self.get_logger().error(f"unusable image: {problem}", throttle_duration_sec=5.0)
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
