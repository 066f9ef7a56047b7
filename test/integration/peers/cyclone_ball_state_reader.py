"""An independent DDS participant (Eclipse Cyclone DDS, no ROS) that reads /ball_state.

It knows only the ROS 2 naming conventions: topic `rt/ball_state`, type
`ball_tracker_msgs::msg::dds_::BallState_` (nested types likewise), plain CDR. It prints the
first sample's fields as JSON and its CDR encoding in hex, then exits (1 after 20 s without).
"""
import json
import os
import sys
import time
from dataclasses import asdict, dataclass

from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float64, int32, uint32
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic


@dataclass
class Time_(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header_(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time_
    frame_id: str


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


# Fast DDS with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST discovers by unicast on loopback.
os.environ.setdefault("CYCLONEDDS_URI", (
    "<General><Interfaces><NetworkInterface name='lo'/></Interfaces>"
    "<AllowMulticast>false</AllowMulticast></General>"
    "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
    "<Peers><Peer address='127.0.0.1'/></Peers></Discovery>"))

participant = DomainParticipant(int(os.environ["ROS_DOMAIN_ID"]))
reader = DataReader(participant, Topic(participant, "rt/ball_state", BallState_),
                    qos=Qos(Policy.Reliability.BestEffort))
deadline = time.monotonic() + 20
while time.monotonic() < deadline:
    for sample in reader.take(1):
        print(json.dumps({"fields": asdict(sample), "cdr_hex": sample.serialize().hex()}), flush=True)
        sys.exit(0)
    time.sleep(0.02)
sys.exit(1)
