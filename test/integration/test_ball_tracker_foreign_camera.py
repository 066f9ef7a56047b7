"""A camera driver on another DDS implementation (Eclipse Cyclone DDS, best effort, as most
camera drivers publish): its 640x480 frames arrive whole, and each one is answered on
/ball_state or, when the CPU is too busy to track them all, skipped as stale and counted
(a newer frame was waiting). A tracker on simulated time (use_sim_time) with no /clock yet,
as before a bag's or a simulator's clock starts, still finds the camera and answers it.

The tracker's image queue is deepened for the test so that every frame DDS delivers reaches
the node and is counted, however busy the machine: only frames lost in transport go missing.
This is what the project's DDS settings (config/dds) are for."""
import json
from pathlib import Path

import numpy as np
import pytest
from ball_tracker_msgs.msg import BallState
from pal_statistics_msgs.msg import Statistics
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo

from ball_balance.vision.synthetic import SyntheticScene
from harness import ROOT, executable, python_cmd

pytestmark = pytest.mark.integration
PUBLISHER = Path(__file__).parent / "peers" / "cyclone_image_publisher.py"
FRAMES = 150                # 5 s at 30 Hz


@pytest.mark.parametrize("reliability, use_sim_time", [("best_effort", False), ("reliable", False),
                                                       ("best_effort", True)])
def test_frames_from_a_cyclone_dds_camera_are_answered(launcher, graph, tmp_path, reliability, use_sim_time):
    scene = SyntheticScene()
    frame = tmp_path / "frame.npy"
    np.save(frame, scene.render((0.08, -0.04), noise_std=2.0)[0])
    info = CameraInfo(width=640, height=480, distortion_model="plumb_bob", k=[float(v) for v in scene.camera.K.ravel()],
                      d=[0.0] * 5)
    info_pub = graph.node.create_publisher(CameraInfo, "/camera/camera_info", qos_profile_sensor_data)
    graph.node.create_timer(0.2, lambda: info_pub.publish(info))
    config = str(ROOT / "config" / "ball_tracker.yaml")
    launcher.start([executable("ball_tracker"), "--ros-args", "--params-file", config,
                    "-p", "startup_frames:=3", "-p", "image_queue_depth:=20",
                    "-p", f"use_sim_time:={str(use_sim_time).lower()}"], name="ball_tracker")
    graph.wait_for_topic("/ball_state", timeout=30)
    answered = set()
    graph.node.create_subscription(BallState, "/ball_state",
                                   lambda m: answered.add((m.header.stamp.sec, m.header.stamp.nanosec)),
                                   qos_profile_sensor_data)
    statistics = {}         # the tracker's latest ~/statistics (one per tracked frame)
    graph.node.create_subscription(Statistics, "/ball_tracker/statistics/full",
                                   lambda m: statistics.update({s.name: s.value for s in m.statistics}), 100)
    options = ["--rate", "30", "--count", str(FRAMES), "--wait-s", "60"]
    options += ["--reliable"] if reliability == "reliable" else []
    camera = launcher.start(python_cmd(str(PUBLISHER), str(frame), *options), name="cyclone_camera")
    graph.spin_until(lambda: not camera.running, timeout=150, what="the Cyclone camera to send its frames")
    report = camera.output().strip().splitlines()
    assert camera.wait(timeout=5) == 0 and json.loads(report[-1])["sent"] == FRAMES, camera.output()
    try:                    # answers still in flight: a deadline, not a sleep
        graph.spin_until(lambda: len(answered) >= FRAMES, timeout=5, what="the last answers")
    except TimeoutError:
        pass                # counted below: a few may be missing
    received = len(answered) + statistics.get("stale_frames", 0)
    assert received >= 0.95 * FRAMES, f"{len(answered)} of {FRAMES} frames answered, {statistics}"
    assert len(answered) >= 10, f"only {len(answered)} of {FRAMES} frames answered"
