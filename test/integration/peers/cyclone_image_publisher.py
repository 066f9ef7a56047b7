"""A camera driver from another DDS implementation: Eclipse Cyclone DDS (no ROS) publishing
sensor_msgs/Image on /camera/image_raw, as many camera drivers and simulators do.

It knows only the ROS 2 naming conventions (topic `rt/camera/image_raw`, type
`sensor_msgs::msg::dds_::Image_`, plain CDR). Frames come from a .npy file (H x W x 3 uint8,
BGR), each stamped with its send time (CLOCK_REALTIME), frame_id "camera".

usage: cyclone_image_publisher.py FRAME.npy --rate 60 --count 300 [--reliable] [--wait-s 20]
Waits until a reader matches (at most --wait-s), publishes, then prints one JSON line
{"sent": n, "matched_after_s": t} and exits (1 when no reader matched).

Configuration: cyclone_common.configure_loopback() (the project's config/dds/cyclonedds.xml
unless CYCLONEDDS_URI says otherwise, discovery on loopback only, as tests and benchmarks run).
"""
import argparse
import json
import os
import sys
import time
from dataclasses import dataclass

import numpy as np
from cyclone_common import Header_, Time_, configure_loopback
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl._machinery import BytesMachine
from cyclonedds.idl.types import sequence, uint8, uint32
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.topic import Topic
from cyclonedds.util import duration


@dataclass
class Image_(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header_
    height: uint32
    width: uint32
    encoding: str
    is_bigendian: uint8
    step: uint32
    data: sequence[uint8]


# sequence<octet> is encoded element by element in Python (~1 s per 640x480 frame); the
# same CDR (uint32 length + the bytes) written as one block, from a bytes value
Image_.__idl__.populate()
for machine in (Image_.__idl__.v1_machine, Image_.__idl__.v2_machine):
    machine.members_machines["data"] = BytesMachine()


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("frame")
    parser.add_argument("--rate", type=float, default=30.0)
    parser.add_argument("--count", type=int, default=300)
    parser.add_argument("--reliable", action="store_true")
    parser.add_argument("--wait-s", type=float, default=20.0)
    parser.add_argument("--topic", default="camera/image_raw")
    args = parser.parse_args()
    configure_loopback()
    image = np.load(args.frame)
    height, width = image.shape[:2]
    data = np.ascontiguousarray(image).tobytes()

    participant = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
    reliability = Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)) if args.reliable \
        else Policy.Reliability.BestEffort
    writer = DataWriter(participant, Topic(participant, f"rt/{args.topic}", Image_),
                        qos=Qos(reliability, Policy.History.KeepLast(1)))
    start = time.monotonic()
    while not writer.get_matched_subscriptions():
        if time.monotonic() - start > args.wait_s:
            print(json.dumps({"sent": 0, "matched_after_s": None}), flush=True)
            return 1
        time.sleep(0.05)
    matched_after_s = time.monotonic() - start
    time.sleep(0.5)                 # let the reader's side finish matching too

    period, next_t = 1.0 / args.rate, time.monotonic()
    for _ in range(args.count):
        sec, nanosec = divmod(time.time_ns(), 1_000_000_000)
        writer.write(Image_(Header_(Time_(sec, nanosec), "camera"), height, width, "bgr8", 0, 3 * width, data))
        next_t += period
        time.sleep(max(0.0, next_t - time.monotonic()))
    time.sleep(0.5)                 # reliable: let the last frames be acknowledged
    print(json.dumps({"sent": args.count, "matched_after_s": round(matched_after_s, 2)}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
