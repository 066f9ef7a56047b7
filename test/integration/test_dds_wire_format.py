"""A BallState from our code is readable by any DDS participant that follows ROS 2's conventions."""
import json
from pathlib import Path

import pytest
from ball_tracker_msgs.msg import BallState
from rclpy.qos import qos_profile_sensor_data
from rclpy.serialization import serialize_message

from harness import python_cmd

READER = Path(__file__).parent / "peers" / "cyclone_ball_state_reader.py"

# CDR of BallState: 4-byte encapsulation header, stamp (8), frame_id (4 + 13 bytes for
# "plate_center\0"), then padding to the 8-byte alignment of x. Padding bytes carry no value
# (Fast DDS leaves them unset), so they are excluded from the byte comparison.
PADDING = slice(4 + 8 + 4 + 13, 36)


@pytest.mark.integration
def test_ball_state_is_byte_correct_for_an_independent_dds_reader(launcher, graph):
    msg = BallState(x=0.125, y=-0.0625, vx=0.5, vy=-1e-3, ball_found=True, tracking_valid=False,
                    markers_found=3, pixel_u=321.5, pixel_v=-0.0)
    msg.header.frame_id = "plate_center"
    msg.header.stamp.sec, msg.header.stamp.nanosec = 1700000000, 123456789
    publisher = graph.node.create_publisher(BallState, "/ball_state", qos_profile_sensor_data)
    reader = launcher.start(python_cmd(str(READER)), name="cyclone_reader")
    graph.spin_until(lambda: publisher.publish(msg) or not reader.running, timeout=90,
                     what="the Cyclone DDS reader to receive a sample")
    assert reader.wait(timeout=5) == 0, reader.output()
    received = json.loads(reader.output().strip().splitlines()[-1])

    assert received["fields"] == {
        "header": {"stamp": {"sec": 1700000000, "nanosec": 123456789}, "frame_id": "plate_center"},
        "x": 0.125, "y": -0.0625, "vx": 0.5, "vy": -1e-3, "ball_found": True, "tracking_valid": False,
        "markers_found": 3, "pixel_u": 321.5, "pixel_v": -0.0}
    ours, theirs = serialize_message(msg), bytes.fromhex(received["cdr_hex"])
    assert ours[:4] == b"\x00\x01\x00\x00", "plain CDR, little endian"
    assert len(ours) == len(theirs)
    assert ours[:PADDING.start] == theirs[:PADDING.start] and ours[PADDING.stop:] == theirs[PADDING.stop:]
