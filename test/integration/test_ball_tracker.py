"""ball_tracker as a real process: synthetic frames in over DDS, /ball_state out."""
import math
import os
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from ball_tracker_msgs.msg import BallState
from pal_statistics_msgs.msg import StatisticsNames, StatisticsValues
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image

from ball_balance.vision.synthetic import SyntheticScene
from harness import ROOT, executable

pytestmark = pytest.mark.integration
CONFIG = str(ROOT / "config" / "ball_tracker.yaml")
BALL_XY = (0.1, -0.05)


def tracker_cmd(*params):
    cmd = [executable("ball_tracker"), "--ros-args", "--params-file", CONFIG, "-p", "startup_frames:=3"]
    for p in params:
        cmd += ["-p", p]
    return cmd


def image_msg(image, stamp_ns, encoding="bgr8"):
    if encoding == "rgb8":
        image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    msg = Image(height=image.shape[0], width=image.shape[1], encoding=encoding, step=3 * image.shape[1])
    msg.data = image.tobytes()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    return msg


class FrameFeeder:
    """Publishes frames (and camera_info) from the test's graph node at 30 Hz (reliable QoS
    unless told otherwise). `lockstep`: the next frame only once the last one was answered
    on /ball_state (or after 1 s), so that a busy machine never makes the tracker skip one."""

    def __init__(self, graph, frames, qos=10, lockstep=False):
        self.frames, self.sent, self.stamps = frames, 0, []
        self.pub = graph.node.create_publisher(Image, "/camera/image_raw", qos)
        self.info_pub = graph.node.create_publisher(CameraInfo, "/camera/camera_info", qos_profile_sensor_data)
        self.timer = graph.node.create_timer(1 / 30, self.tick)
        self.lockstep, self.answered, self.last_sent_s = lockstep, set(), 0.0
        if lockstep:
            graph.node.create_subscription(BallState, "/ball_state", lambda m: self.answered.add(
                (m.header.stamp.sec, m.header.stamp.nanosec)), qos_profile_sensor_data)

    def tick(self):
        if self.lockstep and self.stamps and self.stamps[-1] not in self.answered \
                and time.monotonic() - self.last_sent_s < 1.0:
            return
        self.last_sent_s = time.monotonic()
        msg = self.frames[self.sent % len(self.frames)]
        if isinstance(msg, Image):
            stamp_ns = 1_700_000_000 * 10**9 + self.sent * 33_333_333
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10**9)
            self.stamps.append((msg.header.stamp.sec, msg.header.stamp.nanosec))
        self.pub.publish(msg)
        self.info_pub.publish(self.info)
        self.sent += 1


@pytest.fixture(scope="module")
def scene():
    return SyntheticScene()


def camera_info(scene):
    cam = scene.camera
    info = CameraInfo(width=cam.width, height=cam.height, distortion_model="plumb_bob")
    info.k = [float(v) for v in cam.K.ravel()]
    info.d = [0.0] * 5
    return info


def test_frames_over_dds_give_ball_state_with_truth_flags_and_stamps(launcher, graph, scene):
    tracker = launcher.start(tracker_cmd(), name="ball_tracker")
    image, _ = scene.render(BALL_XY, noise_std=2.0)
    feeder = FrameFeeder(graph, [image_msg(image, 0, "rgb8")])
    feeder.info = camera_info(scene)
    (msg,) = graph.collect(BallState, "/ball_state", qos=qos_profile_sensor_data, timeout=30,
                           predicate=lambda m: m.ball_found)
    assert tracker.running
    assert msg.header.frame_id == "plate_center"
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) in feeder.stamps
    assert msg.tracking_valid and msg.markers_found == 4
    assert math.hypot(msg.x - BALL_XY[0], msg.y - BALL_XY[1]) < 0.002
    assert abs(msg.vx) < 0.05 and abs(msg.vy) < 0.05
    assert 0 < msg.pixel_u < 640 and 0 < msg.pixel_v < 480


def test_plate_pose_with_covariance_has_the_ball_state_stamp_and_the_image_frame(launcher, graph, scene):
    from geometry_msgs.msg import PoseWithCovarianceStamped

    from ball_balance.vision.pose_quality import ball_position_std_m

    launcher.start(tracker_cmd(), name="ball_tracker")
    image, _ = scene.render(BALL_XY)
    frame = image_msg(image, 0)
    frame.header.frame_id = "overhead_camera_optical"
    feeder = FrameFeeder(graph, [frame])
    feeder.info = camera_info(scene)
    poses, states = {}, {}
    graph.node.create_subscription(PoseWithCovarianceStamped, "/plate_pose",
                                   lambda m: poses.__setitem__(stamp_key(m), m), qos_profile_sensor_data)
    graph.node.create_subscription(BallState, "/ball_state",
                                   lambda m: states.__setitem__(stamp_key(m), m), qos_profile_sensor_data)
    graph.spin_until(lambda: any(s.ball_found and k in poses for k, s in states.items()), 40,
                     "a /ball_state with the ball and its /plate_pose")
    key = next(k for k, s in states.items() if s.ball_found and k in poses)
    pose = poses[key]
    assert pose.header.frame_id == "overhead_camera_optical"
    # the synthetic camera looks straight down from camera_height_m
    assert abs(pose.pose.pose.position.z - scene.camera.camera_height_m) < 0.01
    assert 0.0 < ball_position_std_m(pose.pose.covariance) < 0.001


def stamp_key(msg):
    return msg.header.stamp.sec, msg.header.stamp.nanosec


def test_tracker_says_when_the_camera_stops_and_when_it_is_back(launcher, graph, scene):
    tracker = launcher.start(tracker_cmd("camera_timeout_s:=0.5"), name="ball_tracker")
    image, _ = scene.render(BALL_XY)
    feeder = FrameFeeder(graph, [image_msg(image, 0)])
    feeder.info = camera_info(scene)
    graph.collect(BallState, "/ball_state", qos=qos_profile_sensor_data, timeout=30)
    stopped, back = (tracker.output().count(line) for line in ("no camera frame for", "camera frames are back"))
    feeder.timer.cancel()
    graph.spin_until(lambda: tracker.output().count("no camera frame for") > stopped, 20, "the camera-stopped warning")
    feeder.timer.reset()
    graph.spin_until(lambda: tracker.output().count("camera frames are back") > back, 20, "the camera-back line")
    assert tracker.running


def test_best_effort_image_publisher_is_matched_too(launcher, graph, scene):
    tracker = launcher.start(tracker_cmd(), name="ball_tracker")
    image, _ = scene.render(BALL_XY)
    feeder = FrameFeeder(graph, [image_msg(image, 0)], qos=qos_profile_sensor_data)
    feeder.info = camera_info(scene)
    (msg,) = graph.collect(BallState, "/ball_state", qos=qos_profile_sensor_data, timeout=40,
                           predicate=lambda m: m.ball_found)
    assert math.hypot(msg.x - BALL_XY[0], msg.y - BALL_XY[1]) < 0.002
    assert "(best_effort)" in tracker.output()


def test_thread_priority_puts_every_tracker_thread_on_sched_fifo(launcher, graph, scene):
    """DDS's receive threads and the executor that tracks: a frame waits for none of
    them on a busy machine."""
    tracker = launcher.start(tracker_cmd("thread_priority:=1"), name="ball_tracker")
    image, _ = scene.render(BALL_XY)
    feeder = FrameFeeder(graph, [image_msg(image, 0)])
    feeder.info = camera_info(scene)
    graph.collect(BallState, "/ball_state", qos=qos_profile_sensor_data, timeout=40, predicate=lambda m: m.ball_found)
    if "could not give the tracker's threads SCHED_FIFO" in tracker.output():
        pytest.skip("SCHED_FIFO refused here (no CAP_SYS_NICE or rtprio limit)")
    tasks = Path(f"/proc/{tracker.popen.pid}/task")
    policies = {os.sched_getscheduler(int(tid.name)) for tid in tasks.iterdir()}
    assert policies == {os.SCHED_FIFO}


def test_ball_missing_published_every_frame_with_flags(launcher, graph, scene):
    launcher.start(tracker_cmd("max_coast_frames:=2"), name="ball_tracker")
    with_ball, _ = scene.render(BALL_XY)
    without, _ = scene.render(None)
    frames = [image_msg(with_ball, 0)] * 6 + [image_msg(without, 0)] * 6
    feeder = FrameFeeder(graph, frames, lockstep=True)
    feeder.info = camera_info(scene)
    msgs = graph.collect(BallState, "/ball_state", count=30, qos=qos_profile_sensor_data, timeout=30)
    assert all(m.markers_found == 4 for m in msgs)             # one message per frame, ball or not
    flags = [(m.ball_found, m.tracking_valid) for m in msgs]
    lost = next(i for i in range(1, len(flags)) if flags[i - 1] == (True, True) and not flags[i][0])
    # coasting for max_coast_frames = 2 frames, then invalid until the ball is back
    assert flags[lost:lost + 4] == [(False, True), (False, True), (False, False), (False, False)]


def test_bad_frames_are_dropped_counted_and_the_node_keeps_running(launcher, graph, scene):
    tracker = launcher.start(tracker_cmd(), name="ball_tracker")
    good, _ = scene.render(BALL_XY)
    mono = Image(height=4, width=4, encoding="mono8", step=4, data=bytes(16))
    empty = Image(height=0, width=0, encoding="bgr8", step=0)
    truncated = image_msg(good, 0)
    truncated.data = bytes(truncated.data)[:1000]
    feeder = FrameFeeder(graph, [mono, empty, truncated] + [image_msg(good, 0)] * 5)
    feeder.info = camera_info(scene)
    graph.collect(BallState, "/ball_state", qos=qos_profile_sensor_data, timeout=30, predicate=lambda m: m.ball_found)
    # each kind of bad frame is reported once (then throttled per kind)
    graph.spin_until(lambda: all(kind in tracker.output() for kind in ("encoding 'mono8'", "size 0x0", "corrupt:")),
                     20, "a warning for each kind of bad frame")
    names = graph.collect(StatisticsNames, "/ball_tracker/statistics/names", timeout=10,
                          qos=QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                         durability=DurabilityPolicy.TRANSIENT_LOCAL))[0]
    bad_frames = names.names.index("bad_frames")
    values = graph.collect(StatisticsValues, "/ball_tracker/statistics/values", timeout=10,
                           predicate=lambda m: m.names_version == names.names_version and m.values[bad_frames] >= 3)[0]
    stats = dict(zip(names.names, values.values))
    assert stats["total_ms"] > 0 and stats["markers_ms"] > 0 and stats["frames"] > 0
    assert tracker.running


def test_debug_overlay_and_non_finite_or_out_of_limit_plate_cmd(launcher, graph, scene):
    from geometry_msgs.msg import Vector3Stamped

    from ball_balance.control.config import COMMON_SCHEMA
    from ball_balance.nodes.ball_tracker_node import MAX_PLATE_CMD_RAD

    # the bound is the largest command a controller sends: its tilt clip's bound plus a level offset
    (clip,) = [p.max for p in COMMON_SCHEMA if p.name == "max_tilt_cmd_rad"]
    assert MAX_PLATE_CMD_RAD == pytest.approx(clip + math.pi / 2)

    tracker = launcher.start(tracker_cmd("publish_debug_image:=true", "use_plate_cmd:=true"), name="ball_tracker")
    image, _ = scene.render(BALL_XY)
    feeder = FrameFeeder(graph, [image_msg(image, 0)])
    feeder.info = camera_info(scene)
    cmd_pub = graph.node.create_publisher(Vector3Stamped, "/plate_cmd", 10)
    bad = Vector3Stamped()
    bad.vector.x = float("nan")
    absurd = Vector3Stamped()                  # finite, far beyond any tilt: would throw the estimate away
    absurd.vector.x, absurd.vector.y = 1.0e6, -3.0
    good = Vector3Stamped()
    good.vector.x, good.vector.y = 0.01, -0.01
    graph.node.create_timer(0.1, lambda: (cmd_pub.publish(bad), cmd_pub.publish(absurd), cmd_pub.publish(good)))
    start = time.monotonic()
    (overlay,) = graph.collect(Image, "/ball_tracker/debug_image", qos=qos_profile_sensor_data, timeout=30)
    assert (overlay.encoding, overlay.width, overlay.height) == ("bgr8", 640, 480)
    (msg,) = graph.collect(BallState, "/ball_state", qos=qos_profile_sensor_data, timeout=30,
                           predicate=lambda m: m.ball_found)
    assert math.hypot(msg.x - BALL_XY[0], msg.y - BALL_XY[1]) < 0.003   # a small tilt fed forward
    graph.spin_until(lambda: "non-finite /plate_cmd" in tracker.output() and "out-of-limit /plate_cmd (1e+06, -3)"
                     in tracker.output(), 10, "the bad /plate_cmd warnings")
    names = graph.collect(StatisticsNames, "/ball_tracker/statistics/names", timeout=10,
                          qos=QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                         durability=DurabilityPolicy.TRANSIENT_LOCAL))[0]
    bad_plate_cmd = names.names.index("bad_plate_cmd")
    graph.collect(StatisticsValues, "/ball_tracker/statistics/values", timeout=10,
                  predicate=lambda m: m.names_version == names.names_version and m.values[bad_plate_cmd] >= 4)
    # counted every time (10 a second), said once per kind every 5 s while they keep coming (throttled)
    assert tracker.output().count("out-of-limit /plate_cmd") <= 1 + (time.monotonic() - start) / 5.0
    assert tracker.running


def test_a_ball_held_still_under_a_tilt_reads_as_that_level_offset(launcher, graph, scene):
    # the commanded tilt (/plate_cmd) says the ball should roll, the frames say it stays: a
    # constant disturbance holds it, whose level offset, on /ball_level_offset with the frame's
    # stamp, is that tilt
    from geometry_msgs.msg import Vector3Stamped

    launcher.start(tracker_cmd("use_plate_cmd:=true", "disturbance_time_constant_s:=1.0",
                               "estimate_plate_cmd_delay:=false"), name="ball_tracker")
    image, _ = scene.render(BALL_XY)
    feeder = FrameFeeder(graph, [image_msg(image, 0)])
    feeder.info = camera_info(scene)
    cmd_pub = graph.node.create_publisher(Vector3Stamped, "/plate_cmd", 10)
    cmd = Vector3Stamped()
    cmd.vector.x = 0.03
    graph.node.create_timer(0.05, lambda: cmd_pub.publish(cmd))
    offsets = []
    graph.node.create_subscription(Vector3Stamped, "/ball_level_offset", offsets.append, qos_profile_sensor_data)
    graph.spin_until(lambda: offsets and abs(offsets[-1].vector.x - 0.03) < 0.005 and abs(offsets[-1].vector.y) < 0.005,
                     90, "a level offset near (0.03, 0) rad")
    assert stamp_key(offsets[-1]) in feeder.stamps and offsets[-1].header.frame_id == "plate_center"
    # and in ~/statistics, in degrees, for a user to read
    names = graph.collect(StatisticsNames, "/ball_tracker/statistics/names", timeout=10,
                          qos=QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                         durability=DurabilityPolicy.TRANSIENT_LOCAL))[0]
    x_deg = names.names.index("level_offset_x_deg")
    graph.collect(StatisticsValues, "/ball_tracker/statistics/values", timeout=10,
                  predicate=lambda m: m.names_version == names.names_version
                  and abs(m.values[x_deg] - math.degrees(0.03)) < 0.3)


@pytest.mark.parametrize("params, needle", [
    (["calibration_file:=/nonexistent/cam.yaml"], "calibration_file"),
    (["source:=camera", "camera_device:=/dev/video_missing"], "camera_device"),
    (["source:=file", "video_file:=/nonexistent.avi"], "video_file"),
    (["hsv_lower:=[0, 300, 0]"], "hsv_lower"),
], ids=["missing_calibration", "camera_cannot_open", "missing_video", "bad_hsv"])
def test_bad_configuration_exits_non_zero_with_one_line(launcher, params, needle):
    result = launcher.run(tracker_cmd(*params), timeout=60)
    assert result.returncode != 0
    lines = [line for line in (result.stdout + result.stderr).splitlines() if line.strip()]
    assert lines and needle in lines[-1] and "Traceback" not in result.stderr


def test_video_file_source(launcher, graph, scene, tmp_path: Path):
    path = str(tmp_path / "frames.avi")
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (640, 480))
    image, _ = scene.render(BALL_XY)
    for _ in range(20):
        writer.write(image)
    writer.release()
    launcher.start(tracker_cmd("source:=file", f"video_file:={path}", "video_loop:=true"), name="ball_tracker")
    (msg,) = graph.collect(BallState, "/ball_state", qos=qos_profile_sensor_data, timeout=30,
                           predicate=lambda m: m.ball_found)
    assert msg.markers_found == 4
    # no intrinsics here (fronto-parallel view): only the parallax error of the plate-plane fit
    assert math.hypot(msg.x - BALL_XY[0], msg.y - BALL_XY[1]) < 0.006
    assert np.isfinite(msg.vx)
