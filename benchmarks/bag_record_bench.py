"""Bag recorder benchmark: which camera frames `ros2py bag record -a` keeps, and how late it takes them.

A publisher process sends the simulated graph's mix: 640x480 bgr8 frames at 60 Hz on sensor-data
QoS (best effort) and --small-topics reliable JointState topics at the same rate (the graph's
~1500 small messages a second). The recorder records every topic into an MCAP bag beside --busy
processes each keeping a core busy; each process runs in a session of its own, as jobs started
from separate terminals (with autogroup scheduling every session gets an equal share of the
CPUs). After --seconds the recorder gets Ctrl-C (SIGINT) as from a user. From
the bag: frames kept of those published between the first and the last one recorded (each
frame's stamp is its index), and how late each message was taken (its log time, when the
recorder took it out of DDS, minus its publish time). The recorder's CPU time is its rusage.

Variants, in turns in one run: the recorder's interpreter switch interval (`--switch-ms`, the
default compares Python's 5 ms with the recorder's own). A message taken later than its topic's
keep-last depth (ball_balance/cli/bag.py's DEPTH) of publish periods is lost.

usage: python benchmarks/bag_record_bench.py [--seconds 20] [--rounds 2] [--busy 1]
           [--switch-ms 5,0.5] [--small-topics 24]
"""
from __future__ import annotations

import argparse
import os
import signal
import statistics
import struct
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))
sys.path.insert(0, str(ROOT / "benchmarks"))
from controller_manager_bench import Busy  # noqa: E402
from transport_bench import quantile  # noqa: E402

from harness import DomainLease, ros_env  # noqa: E402

RATE_HZ = 60.0
SMALL_TOPIC_PREFIX = "/bench/joints_"  # the publisher's small topics: this and their number

PUBLISHER = textwrap.dedent("""
    import sys, numpy as np, rclpy
    from rclpy.qos import QoSProfile, qos_profile_sensor_data
    from sensor_msgs.msg import Image, JointState
    rate_hz, small_topics, prefix = float(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    rclpy.init()
    node = rclpy.create_node('bag_record_bench_source')
    frames = node.create_publisher(Image, '/camera/image_raw', qos_profile_sensor_data)
    smalls = [node.create_publisher(JointState, f'{prefix}{i}', QoSProfile(depth=10)) for i in range(small_topics)]
    image = Image(height=480, width=640, encoding='bgr8', step=640 * 3)
    image.data = np.random.default_rng(0).integers(0, 255, 640 * 480 * 3, dtype=np.uint8).tobytes()
    joints = JointState(name=[f'joint_{j}' for j in range(6)], position=[0.0] * 6, velocity=[0.0] * 6)
    index = 0
    def tick():
        global index
        image.header.stamp.sec, image.header.stamp.nanosec = divmod(index, 1_000_000_000)
        frames.publish(image)
        for publisher in smalls:
            joints.header.stamp = image.header.stamp
            publisher.publish(joints)
        index += 1
    node.create_timer(1.0 / rate_hz, tick)
    rclpy.spin(node)
""")

# the recorder, with its switch interval replaced before the command runs
RECORDER = textwrap.dedent("""
    import sys
    import ball_balance.cli.bag as bag
    from ball_balance.cli.main import main
    bag.SWITCH_INTERVAL_S = float(sys.argv[1]) / 1000.0
    sys.exit(main(['bag', 'record', '-a', '-o', sys.argv[2], '--max-cache-size', str(10 ** 9)]))
""")


def read_bag(bag: Path) -> dict:
    """Frame indices kept and take delays (ms) per topic kind, from the bag."""
    from mcap.reader import make_reader

    frames, delays_ms = [], {"frames": [], "small": []}
    with open(bag / f"{bag.name}_0.mcap", "rb") as stream:
        for _, channel, message in make_reader(stream).iter_messages():
            delay_ms = (message.log_time - message.publish_time) / 1e6
            if channel.topic == "/camera/image_raw":
                sec, nanosec = struct.unpack_from("<iI", message.data, 4)  # header.stamp, after the CDR preamble
                frames.append(sec * 1_000_000_000 + nanosec)
                delays_ms["frames"].append(delay_ms)
            elif channel.topic.startswith(SMALL_TOPIC_PREFIX):
                delays_ms["small"].append(delay_ms)
    return {"frames": frames, "delays_ms": delays_ms}


def record_once(switch_ms: float, seconds: float, env: dict, folder: Path) -> dict:
    bag = folder / f"bag_{switch_ms:g}ms_{time.monotonic_ns()}"
    recorder = subprocess.Popen([sys.executable, "-c", RECORDER, str(switch_ms), str(bag)], env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                start_new_session=True)
    # subscribed once the bag's progress shows the camera; then record for `seconds`
    deadline = time.monotonic() + 60
    seen = ""
    while "/camera/image_raw" not in seen and time.monotonic() < deadline:
        seen += recorder.stderr.readline()
    time.sleep(seconds)
    recorder.send_signal(signal.SIGINT)
    _, status, usage = os.wait4(recorder.pid, 0)
    recorder.returncode = os.waitstatus_to_exitcode(status)
    if recorder.returncode != 0:
        raise RuntimeError(f"recorder exited {recorder.returncode}: {seen}{recorder.stderr.read()}")
    result = read_bag(bag)
    result["cpu_s"] = usage.ru_utime + usage.ru_stime
    return result


def row(switch_ms: float, result: dict) -> str:
    frames = sorted(set(result["frames"]))
    published = frames[-1] - frames[0] + 1
    delays = result["delays_ms"]
    return (f"{switch_ms:>9g} {len(frames):>5d} / {published:<5d} {published - len(frames):>5d}"
            f" {statistics.median(delays['frames']):>8.1f} {quantile(sorted(delays['frames']), 0.99):>8.1f}"
            f" {max(delays['frames']):>8.1f} {statistics.median(delays['small']):>8.1f}"
            f" {quantile(sorted(delays['small']), 0.99):>8.1f} {result['cpu_s']:>7.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--busy", type=int, default=1)
    parser.add_argument("--switch-ms", default="5,0.5", help="the recorder's switch intervals to compare (ms)")
    parser.add_argument("--small-topics", type=int, default=24)
    args = parser.parse_args()
    switches = [float(v) for v in args.switch_ms.split(",")]
    lease = DomainLease()
    env = ros_env(lease.domain_id)
    source = subprocess.Popen([sys.executable, "-c", PUBLISHER, str(RATE_HZ), str(args.small_topics),
                               SMALL_TOPIC_PREFIX], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    results = []
    try:
        with tempfile.TemporaryDirectory() as folder, Busy(args.busy, own_sessions=True):
            for _ in range(args.rounds):
                for switch_ms in switches:
                    results.append((switch_ms, record_once(switch_ms, args.seconds, env, Path(folder)),
                                    os.getloadavg()[0]))
    finally:
        source.kill()
        source.wait()
        lease.release()
    print(f"640x480 bgr8 at {RATE_HZ:g} Hz best effort + {args.small_topics} reliable topics at {RATE_HZ:g} Hz; "
          f"{args.seconds:g} s per recording, {args.busy} busy process(es), load average "
          f"{min(r[2] for r in results):.1f}-{max(r[2] for r in results):.1f}")
    print("switch ms   frames kept  lost  frame delay ms (med p99 max)  small delay ms (med p99)  cpu s")
    for switch_ms, result, _ in results:
        print(row(switch_ms, result))


if __name__ == "__main__":
    main()
