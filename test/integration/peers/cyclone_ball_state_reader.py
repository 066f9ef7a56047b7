"""An independent DDS participant (Eclipse Cyclone DDS, no ROS) that reads /ball_state.

It knows only the ROS 2 naming conventions: topic `rt/ball_state`, type
`ball_tracker_msgs::msg::dds_::BallState_` (nested types likewise), plain CDR. It prints the
first sample's fields as JSON and its CDR encoding in hex, then exits (1 after 60 s without:
discovery may be slow on a busy machine).
"""
import json
import os
import sys
import time
from dataclasses import asdict, dataclass

from cyclone_common import Header_, configure_loopback
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float64, int32
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic


@dataclass
class BallState_(IdlStruct, typename="ball_tracker_msgs::msg::dds_::BallState_"):
    header: Header_
    x: float64
    y: float64
    vx: float64
    vy: float64
    ball_found: bool
    tracking_valid: bool
    markers_found: int32
    pixel_u: float64
    pixel_v: float64


configure_loopback()
participant = DomainParticipant(int(os.environ["ROS_DOMAIN_ID"]))
reader = DataReader(participant, Topic(participant, "rt/ball_state", BallState_),
                    qos=Qos(Policy.Reliability.BestEffort))
deadline = time.monotonic() + 60
while time.monotonic() < deadline:
    for sample in reader.take(1):
        print(json.dumps({"fields": asdict(sample), "cdr_hex": sample.serialize().hex()}), flush=True)
        sys.exit(0)
    time.sleep(0.02)
sys.exit(1)
