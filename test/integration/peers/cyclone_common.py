"""What the Cyclone DDS peers share: the ROS 2 header types and the loopback discovery that
meets Fast DDS run with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (unicast on 127.0.0.1)."""
import os
from dataclasses import dataclass
from pathlib import Path

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import int32, uint32

PROJECT_CONFIG = Path(__file__).resolve().parents[3] / "config" / "dds" / "cyclonedds.xml"
LOOPBACK_DISCOVERY = ("<General><Interfaces><NetworkInterface name='lo'/></Interfaces>"
                      "<AllowMulticast>false</AllowMulticast></General>"
                      "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
                      "<Peers><Peer address='127.0.0.1'/></Peers></Discovery>")


def configure_loopback() -> None:
    """CYCLONEDDS_URI as given (env.sh: the project's config/dds/cyclonedds.xml; unset: that
    file; set but empty: Cyclone's defaults) plus loopback-only discovery. Call before
    creating the DomainParticipant."""
    base = os.environ.get("CYCLONEDDS_URI", f"file://{PROJECT_CONFIG}")
    os.environ["CYCLONEDDS_URI"] = ",".join(filter(None, [base, LOOPBACK_DISCOVERY]))


@dataclass
class Time_(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header_(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time_
    frame_id: str
