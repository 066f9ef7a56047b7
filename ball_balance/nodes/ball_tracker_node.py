"""`ball_tracker` node: camera frames -> /ball_state (DESIGN.md section 4; issue #5).

A thin rclpy adapter around `ball_balance.vision.tracker.BallTracker`.

Inputs
  source=topic:  `image_topic` (default /camera/image_raw) sensor_msgs/Image, bgr8 or rgb8.
                 QoS keep last 1 (a frame that waited behind another is stale), reliability
                 per `image_qos`: `auto` (default) subscribes reliable when every publisher
                 on the topic is reliable, else best effort (sensor data), and re-checks once
                 a second. Reliable matters: a 640x480 image is fragmented by Fast DDS, and
                 best effort was measured here to lose most frames (notes/ros-from-pypi.md;
                 our integration test saw about 1 in 9 arrive). Publish images reliable.
  source=camera / file: cv2.VideoCapture in a capture thread (`camera_device`, `video_file`).
  `camera_info_topic` (sensor data QoS): intrinsics when no `calibration_file` is given.
  /plate_cmd geometry_msgs/Vector3Stamped (x = u_x, y = u_y, rad): known acceleration for the
                 Kalman prediction when `use_plate_cmd` is true.
Outputs
  /ball_state ball_tracker_msgs/BallState, sensor data QoS (best effort, keep last 5), one per
                 frame (also when nothing is found; the flags say so), stamped with the frame's
                 capture time, frame_id plate_center. A frame that cannot be decoded (wrong
                 encoding, size 0, truncated data) is dropped, counted and reported throttled.
  ~/debug_image  sensor_msgs/Image bgr8 overlay, only with `publish_debug_image`.
  ~/statistics/{full,names,values} (pal_statistics_msgs, the controller manager's
                 StatisticsRegistry): per-stage times (ms) and counters; names latched
                 (transient local), full/values sent per frame only while someone subscribes.
Start-up errors (a bad parameter, a missing calibration file, a camera or file that cannot be
opened) print one line and exit non-zero.
"""
from __future__ import annotations

import math
import threading
from typing import Optional

import cv2
import numpy as np
import rclpy
from ball_tracker_msgs.msg import BallState
from geometry_msgs.msg import Vector3Stamped
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image

from ball_balance.plate_geometry import PLATE_FRAME
from ball_balance.ros.images import decode_image, encode_image
from ball_balance.ros.node_main import StartupError, main_for
from ball_balance.vision.camera import CalibrationError, CameraModel, load_calibration
from ball_balance.vision.config import SOURCE_SCHEMA, TRACKER_SCHEMA, TrackerConfig
from ball_balance.vision.overlay import draw_overlay
from ball_balance.vision.sources import CaptureSource, SourceError
from ball_balance.vision.tracker import STAGES, BallTracker, TrackerResult
from controller_manager_py.parameters import Param, declare_parameters
from controller_manager_py.ros.statistics_publisher import StatisticsRegistry

NODE_SCHEMA = (
    Param("image_qos", "auto", "image subscription reliability: match the publishers, or force one",
          choices=("auto", "reliable", "best_effort")),
    Param("plate_cmd_topic", "/plate_cmd", "commanded tilts (x = u_x, y = u_y, rad) from the controller"),
    Param("publish_debug_image", False, "publish an overlay image on ~/debug_image"),
    Param("publish_statistics", True, "publish per-stage timing on ~/statistics/{names,values}"),
    Param("opencv_threads", 1, "OpenCV worker threads (1: ~1.4 ms per 640x480 frame, leaves cores to others)",
          "", 1, 64),
)
SCHEMA = SOURCE_SCHEMA + TRACKER_SCHEMA + NODE_SCHEMA

BAD_FRAME_WARN_PERIOD_S = 5.0
IMAGE_QOS_CHECK_PERIOD_S = 1.0


class BallTrackerNode(Node):
    def __init__(self):
        super().__init__("ball_tracker")
        self.params = p = declare_parameters(self, SCHEMA)
        config = TrackerConfig.from_values(p)
        cv2.setNumThreads(p["opencv_threads"])
        self.calibration: Optional[CameraModel] = None
        if p["calibration_file"]:
            try:
                self.calibration = load_calibration(p["calibration_file"])
            except CalibrationError as error:
                raise StartupError(f"parameter 'calibration_file': {error}") from None
        self.tracker = BallTracker(config, self.calibration, p["undistort"])
        self._camera_for_size: Optional[tuple] = None
        self._lock = threading.Lock()           # tracker state: capture thread vs callbacks
        self.bad_frames = 0
        self.bad_plate_cmd = 0
        self._last_warned = {}                  # kind of bad frame -> time of its last warning

        self.state_pub = self.create_publisher(BallState, "/ball_state", qos_profile_sensor_data)
        self.debug_pub = (self.create_publisher(Image, "~/debug_image", qos_profile_sensor_data)
                          if p["publish_debug_image"] else None)
        self._last_result: Optional[TrackerResult] = None
        self.statistics = StatisticsRegistry(self, "~/statistics") if p["publish_statistics"] else None
        if self.statistics is not None:
            self.statistics.set_entries(self._statistics_entries())
        self.create_subscription(Vector3Stamped, p["plate_cmd_topic"], self.on_plate_cmd, 10)
        if p["camera_info_topic"] and self.calibration is None:
            self.create_subscription(CameraInfo, p["camera_info_topic"], self.on_camera_info,
                                     qos_profile_sensor_data)

        self.source: Optional[CaptureSource] = None
        if p["source"] == "topic":
            self.image_sub = None
            self.image_reliability: Optional[ReliabilityPolicy] = None
            if p["image_qos"] == "auto":
                self.match_image_qos()
                self.create_timer(IMAGE_QOS_CHECK_PERIOD_S, self.match_image_qos)
            else:
                self._subscribe_images(ReliabilityPolicy.RELIABLE if p["image_qos"] == "reliable"
                                       else ReliabilityPolicy.BEST_EFFORT)
            where = p["image_topic"]
        else:
            try:
                if p["source"] == "camera":
                    self.source = CaptureSource("camera", p["camera_device"], p["camera_width"],
                                                p["camera_height"], p["camera_fps"])
                else:
                    if not p["video_file"]:
                        raise StartupError("parameter 'video_file' must be set when source is 'file'")
                    self.source = CaptureSource("file", p["video_file"], rate_hz=p["video_rate_hz"],
                                                loop=p["video_loop"])
            except SourceError as error:
                param = "camera_device" if p["source"] == "camera" else "video_file"
                raise StartupError(f"parameter '{param}': {error}") from None
            self._stop = threading.Event()
            self._thread = threading.Thread(target=self._capture_loop, name="capture", daemon=True)
            self._thread.start()
            where = f"{p['source']} {p['camera_device'] if p['source'] == 'camera' else p['video_file']}"
        self.get_logger().info(f"tracking the ball from {where} -> /ball_state")

    # -- inputs ----------------------------------------------------------------------------------
    def match_image_qos(self) -> None:
        """image_qos=auto: reliable when all image publishers are, best effort otherwise."""
        publishers = self.get_publishers_info_by_topic(self.params["image_topic"])
        if not publishers:
            return
        reliable = all(info.qos_profile.reliability == ReliabilityPolicy.RELIABLE for info in publishers)
        self._subscribe_images(ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT)

    def _subscribe_images(self, reliability: ReliabilityPolicy) -> None:
        if reliability == self.image_reliability:
            return
        if self.image_sub is not None:
            self.destroy_subscription(self.image_sub)
        qos = QoSProfile(reliability=reliability, history=HistoryPolicy.KEEP_LAST, depth=1)
        self.image_sub = self.create_subscription(Image, self.params["image_topic"], self.on_image, qos)
        self.image_reliability = reliability
        self.get_logger().info(f"subscribed to {self.params['image_topic']} ({reliability.name.lower()})")

    def on_image(self, msg: Image) -> None:
        """A camera frame from the topic: decode (or drop with a reason), track, publish."""
        image, problem = decode_image(msg)
        if problem:
            self._bad_frame(f"{problem}: frame dropped")
            return
        stamp = msg.header.stamp
        if stamp.sec == 0 and stamp.nanosec == 0:            # unstamped: use the receipt time
            stamp = self.get_clock().now().to_msg()
        self.track(image, stamp.sec + stamp.nanosec * 1e-9, stamp)

    def _capture_loop(self) -> None:
        """source=camera/file: read, track and publish until shutdown (not the executor thread)."""
        from builtin_interfaces.msg import Time

        while not self._stop.is_set() and rclpy.ok():
            frame, stamp_s = self.source.read()
            if frame is None:
                if self.source.ended:
                    self.get_logger().info("end of the video file")
                    return
                self._bad_frame("capture returned no frame")
                self._stop.wait(0.05)
                continue
            sec = math.floor(stamp_s)
            self.track(frame, stamp_s, Time(sec=int(sec), nanosec=int((stamp_s - sec) * 1e9)))

    def on_camera_info(self, msg: CameraInfo) -> None:
        model = CameraModel.from_camera_info(msg.width, msg.height, msg.k, msg.d, msg.distortion_model)
        if model is None:
            return
        with self._lock:
            current = self.calibration
            if current is None or not (np.allclose(current.K, model.K) and np.array_equal(current.D, model.D)):
                self.calibration = model
                self._camera_for_size = None
                self.get_logger().info(f"intrinsics from {self.params['camera_info_topic']}: "
                                       f"fx={model.K[0, 0]:.1f} fy={model.K[1, 1]:.1f}")

    def on_plate_cmd(self, msg: Vector3Stamped) -> None:
        u_x, u_y = msg.vector.x, msg.vector.y
        if not (math.isfinite(u_x) and math.isfinite(u_y)):
            self.bad_plate_cmd += 1
            self.get_logger().warn("non-finite /plate_cmd ignored", throttle_duration_sec=5.0)
            return
        now_s = self.get_clock().now().nanoseconds * 1e-9
        self.tracker.set_plate_cmd(u_x, u_y, now_s)

    # -- the work --------------------------------------------------------------------------------
    def track(self, image: np.ndarray, stamp_s: float, stamp_msg) -> None:
        with self._lock:
            self._camera_for(image.shape)
            result = self.tracker.process(image, stamp_s, self.get_clock().now().nanoseconds * 1e-9)
        self.state_pub.publish(ball_state(result, stamp_msg))
        if self.debug_pub is not None and self.debug_pub.get_subscription_count() > 0:
            self.debug_pub.publish(encode_image(draw_overlay(image, self.tracker.plate, result), stamp_msg, "camera"))
        if self.statistics is not None:
            self._last_result = result
            self.statistics.publish()  # values are read only when someone subscribes

    def _camera_for(self, shape) -> None:
        """Give the tracker intrinsics matching the frame size (scaled if calibrated at another)."""
        height, width = shape[:2]
        if self.calibration is None or self._camera_for_size == (width, height):
            return
        self.tracker.set_camera(self.calibration.scaled_to(width, height))
        self._camera_for_size = (width, height)

    def _bad_frame(self, why: str) -> None:
        """Count a dropped frame; warn at most every 5 s per kind of problem (first word)."""
        self.bad_frames += 1
        kind = why.split()[0]
        now = self.get_clock().now().nanoseconds * 1e-9
        if now - self._last_warned.get(kind, -1e9) >= BAD_FRAME_WARN_PERIOD_S:
            self._last_warned[kind] = now
            self.get_logger().warn(f"{why} ({self.bad_frames} bad frames so far)")

    # -- statistics (pal_statistics names/values) ------------------------------------------------
    def _statistics_entries(self):
        """(name, getter) per statistic; getters read the last frame's result lazily."""
        def stage_ms(stage):
            return lambda: 1e3 * self._last_result.timings_s.get(stage, 0.0)

        t, k = self.tracker, self.tracker.kalman
        counters = {
            "frames": lambda: t.frames, "bad_frames": lambda: self.bad_frames,
            "markers_found": lambda: self._last_result.markers_found,
            "ball_found": lambda: self._last_result.ball_found,
            "tracking_valid": lambda: self._last_result.tracking_valid,
            "gated": lambda: k.gated_count, "track_resets": lambda: k.reset_count,
            "bad_plate_cmd": lambda: self.bad_plate_cmd}
        return [(f"{stage}_ms", stage_ms(stage)) for stage in STAGES] + list(counters.items())

    def destroy_node(self):
        if self.source is not None:
            self._stop.set()
            self._thread.join(timeout=2.0)
            self.source.close()
        return super().destroy_node()


def ball_state(result: TrackerResult, stamp_msg) -> BallState:
    msg = BallState(x=result.x, y=result.y, vx=result.vx, vy=result.vy, ball_found=result.ball_found,
                    tracking_valid=result.tracking_valid, markers_found=result.markers_found,
                    pixel_u=result.pixel_u, pixel_v=result.pixel_v)
    msg.header.stamp = stamp_msg
    msg.header.frame_id = PLATE_FRAME
    return msg


main = main_for(BallTrackerNode)
