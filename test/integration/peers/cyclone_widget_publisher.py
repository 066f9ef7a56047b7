"""A publisher of a message type this machine has not installed: Eclipse Cyclone DDS (no ROS)
publishing `acme_msgs/msg/Widget` on /widget, as a package the user never built would.

usage: cyclone_widget_publisher.py [--rate 10] [--seconds 120]
Publishes (best effort) until --seconds have passed or it is stopped.
"""
import argparse
import os
import time
from dataclasses import dataclass

from cyclone_common import configure_loopback
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import int32
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic


@dataclass
class Widget_(IdlStruct, typename="acme_msgs::msg::dds_::Widget_"):
    serial: int32


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--rate", type=float, default=10.0)
    parser.add_argument("--seconds", type=float, default=120.0)
    args = parser.parse_args()
    configure_loopback()
    participant = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
    writer = DataWriter(participant, Topic(participant, "rt/widget", Widget_))
    end = time.monotonic() + args.seconds
    serial = 0
    while time.monotonic() < end:
        writer.write(Widget_(serial=serial))
        serial += 1
        time.sleep(1.0 / args.rate)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
