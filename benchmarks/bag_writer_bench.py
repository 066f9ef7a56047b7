"""Bag writer benchmark: what writing a recording of the simulated graph costs the recorder.

Writes the simulated graph's mix (a 640x480 bgr8 camera frame and 25 small messages per frame,
as `ros2py bag record -a` sees it) to an MCAP file on disk, with the `mcap` package's writer
(chunked, as `bag record` used it before) and with the recorder's own (ball_balance/cli/
mcap_write.py), in turns, beside --busy processes each keeping a core busy. Prints the time
per camera frame (its message and the small ones that came with it) and what 60 Hz would need.

usage: python benchmarks/bag_writer_bench.py [--frames 300] [--rounds 3] [--busy 1]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from controller_manager_bench import Busy  # noqa: E402

from ball_balance.cli.mcap_write import McapWriter  # noqa: E402

FRAME_BYTES = 640 * 480 * 3 + 54  # CDR of a sensor_msgs/Image: header, fields, data
SMALL_BYTES, SMALL_PER_FRAME = 200, 25


def package_writer(stream):
    from mcap.writer import CompressionType, Writer

    return Writer(stream, compression=CompressionType.NONE)


def own_writer(stream):
    return McapWriter(stream)


def frame_times_s(make_writer, frames: int, folder: str) -> list:
    frame, small = os.urandom(FRAME_BYTES), os.urandom(SMALL_BYTES)
    path = os.path.join(folder, "bench.mcap")
    times = []
    with open(path, "wb") as stream:
        writer = make_writer(stream)
        writer.start(profile="ros2", library="bench")
        schema = writer.register_schema(name="sensor_msgs/msg/Image", encoding="ros2msg", data=b"uint32 height")
        images = writer.register_channel(topic="/camera/image_raw", message_encoding="cdr", schema_id=schema,
                                         metadata={})
        states = writer.register_channel(topic="/ball_state", message_encoding="cdr", schema_id=schema, metadata={})
        for i in range(frames):
            started = time.perf_counter()
            writer.add_message(channel_id=images, log_time=i, publish_time=i, data=frame, sequence=i)
            for k in range(SMALL_PER_FRAME):
                writer.add_message(channel_id=states, log_time=i, publish_time=i, data=small, sequence=k)
            times.append(time.perf_counter() - started)
        writer.finish()
    os.remove(path)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--rounds", type=int, default=3, help="each writer this many times, in turns")
    parser.add_argument("--busy", type=int, default=1, help="extra processes each keeping a core busy")
    args = parser.parse_args()
    writers = {"mcap package Writer (chunked)": package_writer, "mcap_write.McapWriter": own_writer}
    results = {name: [] for name in writers}
    with Busy(args.busy), tempfile.TemporaryDirectory() as folder:
        for _ in range(args.rounds):
            for name, make in writers.items():
                results[name] += frame_times_s(make, args.frames, folder)
    print(f"{args.rounds} x {args.frames} camera frames (640x480 bgr8) + {SMALL_PER_FRAME} small messages each, "
          f"{args.busy} busy process(es), load average {os.getloadavg()[0]:.1f}")
    print("| writer | ms per frame, median | p95 | max | share of a core at 60 Hz |")
    print("|---|---|---|---|---|")
    for name, times in results.items():
        ms = sorted(t * 1000 for t in times)
        median, p95 = statistics.median(ms), ms[int(0.95 * (len(ms) - 1))]
        print(f"| {name} | {median:.2f} | {p95:.2f} | {ms[-1]:.1f} | {median * 60 / 1000:.0%} |")


if __name__ == "__main__":
    main()
