"""The tracker on the simulated camera over DDS: MuJoCo arm + camera (ros2_control_node with
MujocoSystem) -> /camera/image_raw + /camera/camera_info -> ball_tracker -> /ball_state,
compared with /sim/ball_truth at the same stamps."""
import pytest
from ball_tracker_msgs.msg import BallState
from rclpy.qos import qos_profile_sensor_data
from test_sim_arm import start_sim

from harness import ROOT, executable

pytestmark = pytest.mark.integration


def stamp_ns(msg):
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def test_tracker_on_the_simulated_camera_matches_the_truth(launcher, graph, tmp_path):
    start_sim(launcher, tmp_path)
    tracker = launcher.start([executable("ball_tracker"), "--ros-args", "--params-file",
                              str(ROOT / "config" / "ball_tracker.yaml")], name="ball_tracker")
    truths = {}
    graph.node.create_subscription(BallState, "/sim/ball_truth", lambda m: truths.__setitem__(stamp_ns(m), m),
                                   qos_profile_sensor_data)
    states = graph.collect(BallState, "/ball_state", count=5, qos=qos_profile_sensor_data, timeout=90,
                           predicate=lambda m: m.ball_found)
    assert tracker.running
    for state in states:
        assert state.tracking_valid and state.markers_found == 4 and state.header.frame_id == "plate_center"
        # the truth sample nearest the frame's capture stamp (truth comes at the loop rate)
        nearest = min(truths, key=lambda t: abs(t - stamp_ns(state)))
        assert abs(nearest - stamp_ns(state)) < 5_000_000
        truth = truths[nearest]
        assert abs(state.x - truth.x) < 0.002 and abs(state.y - truth.y) < 0.002
