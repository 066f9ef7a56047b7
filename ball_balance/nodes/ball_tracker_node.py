"""`ball_tracker` node: camera frames -> /ball_state (docs/design.md section 4; issue #5).

A thin rclpy adapter around `ball_balance.vision.tracker.BallTracker`.

Inputs
  source=topic:  `image_topic` (default /camera/image_raw) sensor_msgs/Image, bgr8 or rgb8.
                 QoS keep last `image_queue_depth` (1), reliability per `image_qos`: `auto` (default) subscribes
                 reliable when every publisher on the topic is reliable, else best effort
                 (sensor data), and re-checks once a second. Whole frames at full rate over
                 best effort need the DDS settings of config/dds (docs/transport.md).
                 The subscription takes frames serialized and reads the pixels in place
                 (ros/images.py: image_from_cdr), and its callback tracks the frame itself
                 (no hand-over to another thread: about 1 ms less). With the default
                 queue depth 1, DDS keeps only the newest frame while the node works, so
                 the tracker never works on an old frame while a newer one waits, and
                 never queues under load. With a deeper queue the callback first takes
                 every frame queued behind its own and tracks only the newest; the others
                 are skipped and counted (`stale_frames`). Frames that never reached the
                 callback (replaced in the DDS queue while the node was busy, or lost in
                 transport) show as gaps in the publisher's sequence numbers
                 (`skipped_frames`).
  source=camera / file: cv2.VideoCapture in a capture thread (`camera_device`, `video_file`).
  `camera_info_topic` (sensor data QoS): intrinsics when no `calibration_file` is given.
  /plate_cmd geometry_msgs/Vector3Stamped (x = u_x, y = u_y, rad): known acceleration for the
                 Kalman prediction when `use_plate_cmd` is true. A non-finite command, or one
                 beyond MAX_PLATE_CMD_RAD, is ignored, counted (`bad_plate_cmd`) and logged throttled.
Outputs
  /ball_state ball_tracker_msgs/BallState, sensor data QoS (best effort, keep last 5), one per
                 frame (also when nothing is found; the flags say so), stamped with the frame's
                 capture time, frame_id plate_center. A frame that cannot be decoded (wrong
                 encoding, size 0, truncated data) is dropped, counted and reported throttled.
  /plate_pose    geometry_msgs/PoseWithCovarianceStamped, sensor data QoS, one per frame with
                 the identical stamp: plate_center in the camera frame (frame_id = the
                 image's), covariance 6x6 [x y z rx ry rz] (m^2, rad^2) from the marker fit;
                 every variance +inf when the frame gave no usable pose
                 (ball_balance/vision/pose_quality.py; its ball_position_std_m() reduces
                 the covariance to the ball-position error it causes).
  /ball_level_offset geometry_msgs/Vector3Stamped, sensor data QoS, one per frame with the
                 identical stamp, only with `disturbance_time_constant_s` > 0: the filter's
                 constant disturbance as a plate-level offset (x = u_x, y = u_y, rad, the
                 /plate_cmd convention): the tilt that holds the ball still. The controllers
                 cancel it.
  ~/debug_image  sensor_msgs/Image bgr8 overlay, only with `publish_debug_image`.
  ~/statistics/{full,names,values} (pal_statistics_msgs, the controller manager's
                 StatisticsRegistry): per-stage times (ms) and counters (plate_cmd_delay_ms: the
                 command -> plate delay the filter uses, estimate_plate_cmd_delay; with the
                 disturbance state level_offset_{x,y}_deg, the plate's level offset in degrees,
                 and disturbance_changes); names latched
                 (transient local), full/values sent per frame only while someone subscribes.
A camera that stops (no frame for `camera_timeout_s`, a dead driver) is reported once with a
warning, and its return with an info line.
Start-up errors (a bad parameter, a missing calibration file, a camera or file that cannot be
opened) print one line and exit non-zero.
"""
from __future__ import annotations

import math
import sys
import threading
import time
from typing import Optional

import cv2
import numpy as np
import rclpy
from ball_tracker_msgs.msg import BallState
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseWithCovarianceStamped, Vector3Stamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image

from ball_balance.control.safety import LEVEL_OFFSET_TOPIC
from ball_balance.plate_geometry import PLATE_FRAME
from ball_balance.ros.images import decode_image, encode_image, image_from_cdr
from ball_balance.rotations import matrix_to_quaternion
from ball_balance.vision.camera import CalibrationError, CameraModel, load_calibration
from ball_balance.vision.config import SOURCE_SCHEMA, TRACKER_SCHEMA, TrackerConfig
from ball_balance.vision.overlay import draw_overlay
from ball_balance.vision.pose_quality import UNUSABLE_COVARIANCE
from ball_balance.vision.sources import CaptureSource, SourceError
from ball_balance.vision.tracker import STAGES, BallTracker, TrackerResult
from controller_manager_py.parameters import Param, declare_parameters
from controller_manager_py.realtime import reuse_freed_memory, set_process_realtime_priority
from controller_manager_py.ros.node_main import StartupError, main_for
from controller_manager_py.ros.statistics_publisher import StatisticsRegistry

NODE_SCHEMA = (
    Param("image_qos", "auto", "image subscription reliability: match the publishers, or force one",
          choices=("auto", "reliable", "best_effort")),
    Param("plate_cmd_topic", "/plate_cmd", "commanded tilts (x = u_x, y = u_y, rad) from the controller"),
    Param("publish_debug_image", False, "publish an overlay image on ~/debug_image"),
    Param("publish_statistics", True, "publish per-stage timing on ~/statistics/{names,values}"),
    Param("image_queue_depth", 1,
          "DDS queue of the image subscription: 1 keeps only the newest frame; more lets every "
          "delivered frame reach the node, which tracks the newest and counts the others as stale "
          "(each costs ~0.3 ms to take)", "frames", 1, 100),
    Param("camera_timeout_s", 1.0, "warn when no frame arrives for this long (camera stopped or died)",
          "s", 0.05, 3600.0),
    Param("opencv_threads", 1, "OpenCV worker threads (1: about 1.1-1.9 ms per 640x480 frame, leaves cores to others)",
          "", 1, 64),
    Param("thread_priority", 40,
          "SCHED_FIFO priority (1-99) of every thread of the tracker (its DDS receive threads, the executor "
          "that takes and tracks frames, a capture thread), so that a busy machine does not delay a frame; below "
          "the controllers' 45, above the simulated camera's 30; 0: normal scheduling. Needs CAP_SYS_NICE or an "
          "rtprio limit (else one warning, normal scheduling)", "", 0, 99),
)
SCHEMA = SOURCE_SCHEMA + TRACKER_SCHEMA + NODE_SCHEMA

BAD_FRAME_WARN_PERIOD_S = 5.0
IMAGE_QOS_CHECK_PERIOD_S = 1.0
CAMERA_FRAME_ID = "camera"          # frame_id of /plate_pose when the image carries none
# The largest /plate_cmd per axis (rad) a controller sends: its tilt clip (max_tilt_cmd_rad, at most
# 0.35 rad, control/config.py; not imported: it would load the MPC's solver here) less the
# disturbance's level offset asin(d / k g), at most pi/2 in size. Anything larger is no tilt at
# all, and fed forward would throw the estimate off the plate.
MAX_PLATE_CMD_RAD = 0.35 + math.pi / 2


class BallTrackerNode(Node):
    def __init__(self):
        super().__init__("ball_tracker")
        self.params = p = declare_parameters(self, SCHEMA)
        config = TrackerConfig.from_values(p)
        cv2.setNumThreads(p["opencv_threads"])
        # source camera/file: two Python threads share the interpreter lock (capture thread,
        # executor); a 1 ms switch interval (default 5 ms) bounds how long either waits for it
        sys.setswitchinterval(0.001)
        # each frame's buffers (DDS sample, message, image) are freed and allocated again:
        # reuse the memory instead of mapping fresh pages per frame (~1 ms of page faults)
        reuse_freed_memory()
        self.calibration: Optional[CameraModel] = None
        if p["calibration_file"]:
            try:
                self.calibration = load_calibration(p["calibration_file"])
            except CalibrationError as error:
                raise StartupError(f"parameter 'calibration_file': {error}") from None
        self.tracker = BallTracker(config, self.calibration, p["undistort"])
        self._camera_for_size: Optional[tuple] = None
        self._last_camera_info: Optional[tuple] = None
        self._lock = threading.Lock()           # tracker state: capture thread vs callbacks
        self.bad_frames = 0
        self.bad_plate_cmd = 0
        self._last_warned = {}                  # kind of bad frame -> time of its last warning

        self.state_pub = self.create_publisher(BallState, "/ball_state", qos_profile_sensor_data)
        self.pose_pub = self.create_publisher(PoseWithCovarianceStamped, "/plate_pose", qos_profile_sensor_data)
        self.level_pub = (self.create_publisher(Vector3Stamped, LEVEL_OFFSET_TOPIC, qos_profile_sensor_data)
                          if config.disturbance_time_constant_s > 0.0 else None)
        self.stale_frames = 0                   # taken from a deeper queue behind a newer one, never tracked
        self.out_of_order_frames = 0            # stamped before the last tracked frame
        self.skipped_frames = 0                 # gaps in the publisher's sequence numbers
        self._last_sequence: Optional[int] = None
        self._last_stamp_ns = -1
        # s, last tracked frame (statistics): DDS write -> DDS receipt (transport), -> callback
        # (take), decode, publish; node clock - stamp at receipt and after publishing
        # (age_at_*: a camera on another clock shows its offset too)
        self._frame_times = {"transport": 0.0, "take": 0.0, "decode": 0.0, "publish": 0.0,
                             "age_at_receipt": 0.0, "age_at_publish": 0.0}
        self._last_frame_mono: Optional[float] = None  # monotonic receipt time of the last frame
        self._camera_silent = False
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

        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.source: Optional[CaptureSource] = None
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        if p["source"] == "topic":
            self.image_sub = None
            self.image_reliability: Optional[ReliabilityPolicy] = None
            if p["image_qos"] == "auto":
                self.match_image_qos()
                # discovery and camera silence are wall-clock matters: with use_sim_time a
                # timer on the node clock stops until /clock ticks, and a tracker started
                # before a bag's or a simulator's /clock never subscribed to its camera
                self.create_timer(IMAGE_QOS_CHECK_PERIOD_S, self.match_image_qos, clock=steady)
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
            self._thread = threading.Thread(target=self._capture_loop, name="capture", daemon=True)
            self._thread.start()
            where = f"{p['source']} {p['camera_device'] if p['source'] == 'camera' else p['video_file']}"
        self.create_timer(min(0.5, p["camera_timeout_s"] / 2.0), self.watch_camera, clock=steady)
        # last, once every thread exists (threads started later inherit the policy)
        if p["thread_priority"] > 0 and not set_process_realtime_priority(p["thread_priority"]):
            self.get_logger().warning(f"could not give the tracker's threads SCHED_FIFO priority "
                                      f"{p['thread_priority']} (needs CAP_SYS_NICE or an rtprio limit); running at "
                                      "normal priority, frames wait longer on a busy machine")
        self._frames_from = where

    def announce(self) -> None:
        """The start-up line (controller_manager_py.ros.node_main.run_node)."""
        self.get_logger().info(f"tracking the ball from {self._frames_from} -> /ball_state, /plate_pose")

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
        qos = QoSProfile(reliability=reliability, history=HistoryPolicy.KEEP_LAST,
                         depth=self.params["image_queue_depth"])
        self.image_sub = self.create_subscription(Image, self.params["image_topic"], self.on_image, qos, raw=True)
        self.image_reliability = reliability
        self.get_logger().info(f"subscribed to {self.params['image_topic']} ({reliability.name.lower()})")

    def on_image(self, msg: bytes, info: dict) -> None:
        """A camera frame from the topic, serialized (executor thread): track the newest one now."""
        callback_wall_ns = time.time_ns()
        self._count_gaps(info)
        if self.params["image_queue_depth"] > 1:
            msg, info = self._newest_queued(msg, info)
        self._last_frame_mono = time.monotonic()
        try:
            self._track_message(msg, self.get_clock().now().nanoseconds, callback_wall_ns,
                                info.get("source_timestamp"), info.get("received_timestamp"))
        except Exception as error:  # noqa: BLE001 - one bad frame must not end tracking
            self.get_logger().error(f"frame not tracked: {type(error).__name__}: {error}",
                                    throttle_duration_sec=5.0)

    def _count_gaps(self, info: dict) -> None:
        """Frames missing between this one and the last one taken (never delivered)."""
        sequence = info.get("publication_sequence_number")
        if sequence is not None:
            if self._last_sequence is not None and sequence > self._last_sequence + 1:
                self.skipped_frames += sequence - self._last_sequence - 1
            self._last_sequence = sequence

    def _newest_queued(self, msg: bytes, info: dict) -> tuple:
        """image_queue_depth > 1: take the frames queued behind `msg` and return the newest;
        the others are counted stale."""
        sub = self.image_sub
        while True:
            # what the executor itself calls to take a message (rclpy has no public take)
            with sub.handle:
                taken = sub.handle.take_message(sub.msg_type, sub.raw)
            if taken is None:
                return msg, info
            self.stale_frames += 1
            msg, info = taken
            self._count_gaps(info)

    def _track_message(self, serialized: bytes, received_ns: int, callback_wall_ns: int,
                       written_wall_ns: Optional[int], delivered_wall_ns: Optional[int]) -> None:
        times = self._frame_times
        start = time.monotonic()
        if written_wall_ns and delivered_wall_ns:          # the DDS sample's own wall-clock times
            times["transport"] = (delivered_wall_ns - written_wall_ns) * 1e-9
            times["take"] = (callback_wall_ns - delivered_wall_ns) * 1e-9
        try:
            msg = image_from_cdr(serialized)
        except Exception as error:  # noqa: BLE001 - ValueError, or rclpy's for other encodings
            self._bad_frame(f"corrupt: {error}: frame dropped")
            return
        stamp = msg.header.stamp
        stamp_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        if stamp_ns == 0:                                     # unstamped: use the receipt time
            stamp_ns = received_ns
            sec, nanosec = divmod(received_ns, 1_000_000_000)
            stamp = Time(sec=sec, nanosec=nanosec)
        elif stamp_ns <= self._last_stamp_ns:
            self.out_of_order_frames += 1                     # older than what was tracked
            return
        times["age_at_receipt"] = (received_ns - stamp_ns) * 1e-9
        image, problem = decode_image(msg)
        if problem:
            self._bad_frame(f"{problem}: frame dropped")
            return
        times["decode"] = time.monotonic() - start
        self._last_stamp_ns = stamp_ns
        self.track(image, stamp_ns * 1e-9, stamp, msg.header.frame_id or CAMERA_FRAME_ID)

    def _capture_loop(self) -> None:
        """source=camera/file: read, track and publish until shutdown (not the executor thread)."""
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
            self._last_frame_mono = time.monotonic()
            self.track(frame, stamp_s, Time(sec=int(sec), nanosec=int((stamp_s - sec) * 1e9)), CAMERA_FRAME_ID)

    def on_camera_info(self, msg: CameraInfo) -> None:
        raw = (msg.width, msg.height, tuple(msg.k), tuple(msg.d), msg.distortion_model)
        if raw == self._last_camera_info:
            return          # the same intrinsics with every frame: nothing to do (cheap check)
        self._last_camera_info = raw
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
            self.get_logger().warn(f"non-finite /plate_cmd ignored ({self.bad_plate_cmd} bad so far)",
                                   throttle_duration_sec=5.0)
            return
        if max(abs(u_x), abs(u_y)) > MAX_PLATE_CMD_RAD:
            self.bad_plate_cmd += 1
            self.get_logger().warn(f"out-of-limit /plate_cmd ({u_x:g}, {u_y:g}) rad ignored (beyond "
                                   f"{MAX_PLATE_CMD_RAD:.3g} rad; {self.bad_plate_cmd} bad so far)",
                                   throttle_duration_sec=5.0)
            return
        now_s = self.get_clock().now().nanoseconds * 1e-9
        self.tracker.set_plate_cmd(u_x, u_y, now_s)

    # -- the work --------------------------------------------------------------------------------
    def track(self, image: np.ndarray, stamp_s: float, stamp_msg, camera_frame: str) -> None:
        with self._lock:
            self._camera_for(image.shape)
            result = self.tracker.process(image, stamp_s, self.get_clock().now().nanoseconds * 1e-9)
        start = time.monotonic()
        # the pose first: a controller that pairs them steps as soon as the state arrives
        self.pose_pub.publish(plate_pose(result, stamp_msg, camera_frame))
        if self.level_pub is not None and result.level_offset_rad is not None:
            level = Vector3Stamped()
            level.header.stamp, level.header.frame_id = stamp_msg, PLATE_FRAME
            level.vector.x, level.vector.y = result.level_offset_rad
            self.level_pub.publish(level)
        self.state_pub.publish(ball_state(result, stamp_msg))
        now = self.get_clock().now().nanoseconds
        self._frame_times["publish"] = time.monotonic() - start
        self._frame_times["age_at_publish"] = now * 1e-9 - stamp_s
        if self.debug_pub is not None and self.debug_pub.get_subscription_count() > 0:
            overlay = draw_overlay(image, self.tracker.plate, result)
            self.debug_pub.publish(encode_image(overlay, stamp_msg, camera_frame))
        if self.statistics is not None:
            self._last_result = result
            self.statistics.publish()  # values are read only when someone subscribes

    def watch_camera(self) -> None:
        """Say once when frames stop coming (a dead camera driver), and when they are back."""
        last = self._last_frame_mono
        if last is None:
            return
        silent_s = time.monotonic() - last
        if silent_s > self.params["camera_timeout_s"] and not self._camera_silent:
            self._camera_silent = True
            self.get_logger().warn(f"no camera frame for {silent_s:.1f} s: the camera stopped or its driver died; "
                                   "/ball_state paused")
        elif silent_s <= self.params["camera_timeout_s"] and self._camera_silent:
            self._camera_silent = False
            self.get_logger().info("camera frames are back")

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
        def frame_ms(what):
            return lambda: 1e3 * self._frame_times[what]

        counters.update({"stamp_s": lambda: self._last_result.stamp_s,    # the frame these values are of
                         "stale_frames": lambda: self.stale_frames, "skipped_frames": lambda: self.skipped_frames,
                         "out_of_order_frames": lambda: self.out_of_order_frames,
                         "position_std_mm": lambda: 1e3 * self._last_result.position_std_m,
                         # the command -> plate delay the filter uses (estimated or configured)
                         "plate_cmd_delay_ms": lambda: 1e3 * t.plate_cmds.delay_s})
        if k.disturbance_state:   # a user learns here that the plate is not level
            def level_deg(axis):
                return lambda: math.degrees(k.level_offset_rad(t.plate_cmds.k_g)[axis])
            counters.update({"level_offset_x_deg": level_deg(0), "level_offset_y_deg": level_deg(1),
                             "disturbance_changes": lambda: k.disturbance_changes})
        frame = [(f"{what}_ms", frame_ms(what)) for what in self._frame_times]
        return [(f"{stage}_ms", stage_ms(stage)) for stage in STAGES] + frame + list(counters.items())

    def destroy_node(self):
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self.source is not None:
            self.source.close()
        return super().destroy_node()


def ball_state(result: TrackerResult, stamp_msg) -> BallState:
    msg = BallState(x=result.x, y=result.y, vx=result.vx, vy=result.vy, ball_found=result.ball_found,
                    tracking_valid=result.tracking_valid, markers_found=result.markers_found,
                    pixel_u=result.pixel_u, pixel_v=result.pixel_v)
    msg.header.stamp = stamp_msg
    msg.header.frame_id = PLATE_FRAME
    return msg


def plate_pose(result: TrackerResult, stamp_msg, camera_frame: str) -> PoseWithCovarianceStamped:
    """plate_center in the camera frame with the fit's covariance (UNUSABLE without a pose)."""
    msg = PoseWithCovarianceStamped()
    msg.header.stamp = stamp_msg
    msg.header.frame_id = camera_frame
    if result.plate_pose is None:
        msg.pose.covariance = UNUSABLE_COVARIANCE
        return msg
    R_CP, t_CP = result.plate_pose
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    p.x, p.y, p.z = (float(v) for v in t_CP)
    q.x, q.y, q.z, q.w = matrix_to_quaternion(R_CP)
    # a float64 array of 36 is the field's own type: assigned without a per-element check
    msg.pose.covariance = np.array(result.pose_covariance, dtype=np.float64).ravel()
    return msg


main = main_for(BallTrackerNode)
