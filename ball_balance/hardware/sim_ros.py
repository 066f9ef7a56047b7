"""The simulated arm's ROS side: publishers and the reset service on the manager's node.

Used by MujocoSystem (ball_balance/hardware/mujoco_system.py); built once in on_configure.
Publishing is called from the real-time loop (truth, clock, detections: small messages at
their own rates) and from the camera thread (images).
"""
from __future__ import annotations

from typing import Callable, Mapping

import numpy as np
from ball_tracker_msgs.msg import BallState
from builtin_interfaces.msg import Time
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Bool
from std_srvs.srv import Trigger

from ball_balance.plate_geometry import PLATE_FRAME
from ball_balance.robot import BASE_FRAME
from ball_balance.ros.images import encode_image
from ball_balance.sim.config import camera_intrinsics
from ball_balance.tf.ros import StaticTransformBroadcaster, transform_to_msg
from ball_balance.tf.transform import Transform

# A reliable publisher also serves sensor-data (best-effort) subscribers; reliable ones then get
# every frame (over best effort Fast DDS loses most fragmented 640x480 frames here).
IMAGE_RELIABLE = QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)


def stamp(time_s: float) -> Time:
    sec = int(time_s // 1)
    return Time(sec=sec, nanosec=min(999_999_999, int(round((time_s - sec) * 1e9))))


class SimRosIo:
    def __init__(self, node, world, params: Mapping[str, object], on_reset: Callable[[], None]):
        self.node, self.world, self.params = node, world, params
        self.logger = node.get_logger()
        image_qos = IMAGE_RELIABLE if params["image_reliable"] else qos_profile_sensor_data
        self.image_pub = node.create_publisher(Image, "/camera/image_raw", image_qos)
        self.info_pub = node.create_publisher(CameraInfo, "/camera/camera_info", image_qos)
        self.truth_pub = node.create_publisher(BallState, "/sim/ball_truth", qos_profile_sensor_data)
        self.dropped_pub = node.create_publisher(Bool, "/sim/ball_dropped", LATCHED)
        self.clock_pub = node.create_publisher(Clock, "/clock", QoSProfile(depth=1))
        self.detection_pub = (node.create_publisher(BallState, "/ball_state", qos_profile_sensor_data)
                              if params["truth_fed"] else None)
        self._on_reset = on_reset
        self._closed = False
        # stamps = sim time + this offset: 0 with sim_time (the component owns /clock), else
        # the wall-clock time at start, so stamps compare with wall-clock nodes
        self.stamp_offset_s = 0.0
        self.reset_srv = node.create_service(Trigger, "/sim/reset_ball", self._handle_reset)
        self._dropped = None
        self._camera_info = self._make_camera_info()
        self.static_tf = StaticTransformBroadcaster(node)
        self.static_tf.send_transform(self._camera_transform())
        self._clock = Clock()
        self.update_dropped(False, None)

    def _camera_transform(self):
        """base_link -> camera frame (optical convention: z forward, x right, y down in the image)."""
        c_W, R_WC = self.world.camera_pose()  # MuJoCo camera axes: x right, y up, looking along -z
        R_W_optical = R_WC @ np.diag([1.0, -1.0, -1.0])
        transform = Transform.from_values(tuple(c_W), tuple(Rotation.from_matrix(R_W_optical).as_quat()))
        return transform_to_msg(transform, BASE_FRAME, self.params["camera_frame_id"], None)

    def _make_camera_info(self) -> CameraInfo:
        camera = self.world.config.camera
        fx, fy, cx, cy = camera_intrinsics(camera)
        info = CameraInfo(width=camera.width_px, height=camera.height_px, distortion_model="plumb_bob")
        info.header.frame_id = self.params["camera_frame_id"]
        info.d = [0.0] * 5
        info.k = [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]
        info.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        info.p = [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]
        return info

    def _publish(self, publisher, msg) -> None:
        """Publish; after close() or the context's shutdown (Ctrl-C, SIGTERM) quietly do nothing."""
        try:
            publisher.publish(msg)
        except Exception:  # noqa: BLE001 - rclpy raises RCLError/InvalidHandle types at shutdown
            if self.node.context.ok() and not self._closed:
                raise

    # ---- camera thread ------------------------------------------------------------------
    def publish_image(self, image_bgr, time_s: float) -> None:
        msg = encode_image(image_bgr, stamp(time_s + self.stamp_offset_s), self.params["camera_frame_id"])
        self._camera_info.header.stamp = msg.header.stamp
        self._publish(self.image_pub, msg)
        self._publish(self.info_pub, self._camera_info)

    # ---- real-time loop -----------------------------------------------------------------
    def publish_truth(self, truth) -> None:
        """The true ball state; pixel_u/v: the ball centre projected into the camera image."""
        frame = self.world.frame_truth(truth)
        msg = BallState(x=truth.x, y=truth.y, vx=truth.vx, vy=truth.vy, ball_found=not truth.dropped,
                        tracking_valid=not truth.dropped, markers_found=4,
                        pixel_u=frame.pixel_u, pixel_v=frame.pixel_v)
        msg.header.stamp = stamp(truth.time_s + self.stamp_offset_s)
        msg.header.frame_id = PLATE_FRAME
        self._publish(self.truth_pub, msg)

    def publish_detection(self, time_s: float, x: float, y: float) -> None:
        """truth_fed mode: a tracker-like BallState from the (noisy) truth; no Kalman velocity."""
        truth = self.world.ball_truth()
        msg = BallState(x=x, y=y, vx=truth.vx, vy=truth.vy, ball_found=not truth.dropped,
                        tracking_valid=not truth.dropped, markers_found=4)
        msg.header.stamp = stamp(time_s + self.stamp_offset_s)
        msg.header.frame_id = PLATE_FRAME
        self._publish(self.detection_pub, msg)

    def publish_clock(self, time_s: float) -> None:
        self._clock.clock = stamp(time_s)
        self._publish(self.clock_pub, self._clock)

    def update_dropped(self, dropped: bool, truth) -> None:
        if dropped == self._dropped:
            return
        self._dropped = dropped
        self._publish(self.dropped_pub, Bool(data=dropped))
        if dropped:
            self.logger.warning(f"ball dropped off the plate at t={truth.time_s:.3f} s "
                                f"(x={truth.x:+.3f} m, y={truth.y:+.3f} m); call /sim/reset_ball to put it back")

    # ---- executor thread ----------------------------------------------------------------
    def _handle_reset(self, request, response):
        self._on_reset()
        response.success, response.message = True, "ball reset to the plate centre"
        return response

    def close(self) -> None:
        self._closed = True
        for entity in (self.image_pub, self.info_pub, self.truth_pub, self.dropped_pub, self.clock_pub,
                       self.detection_pub):
            if entity is not None:
                self.node.destroy_publisher(entity)
        self.node.destroy_service(self.reset_srv)
