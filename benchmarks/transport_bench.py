"""Transport benchmark: camera frames through the ball_tracker, and BallState one hop.

1. Images (default): a camera publisher in its own process -> the ball_tracker executable
   -> /ball_state received in this process, all on a private ROS domain with the project's
   DDS settings (config/dds, applied by env.sh). Publishers: Eclipse Cyclone DDS (a foreign
   camera driver, test/integration/peers/cyclone_image_publisher.py) and rclpy/Fast DDS;
   best effort (sensor data, as docs/design.md specifies) and reliable; 640x480 and 960x540.
   Each frame is stamped with its send time (before the publisher converts and serialises
   it), so latency = receipt of its /ball_state here - frame stamp (one clock, one host).
   Prints frames answered (%) and latency median/p95/p99/max, then the tracker's own
   per-frame stages from its ~/statistics (transport: DDS write -> DDS receipt; take:
   receipt -> callback; decode; track; publish), and frames it skipped: stale (a newer one
   waited; only with image_queue_depth > 1) and never delivered (sequence gaps: lost, or
   replaced in the tracker's DDS queue of 1 by a newer one while it was busy). Then, per case,
   the whole chain split at the DDS samples' own write/receipt times: camera write (stamp ->
   image written), image transport, tracker take, track+publish (-> /ball_state written),
   state transport (-> receipt here), receiver take (-> callback here), as median / p99 /
   mean over the slowest 2 % of frames: where the tail comes from.
2. BallState one hop (--ball-state): a publisher process at --rate Hz, sensor data and
   reliable QoS, receipt - send time.

usage: python benchmarks/transport_bench.py [--seconds 5] [--image-rate 60]
           [--cases cyclone-be-640,...] [--tracker-param thread_priority:=0] [--realtime 30 [--receiver-only]]
           [--ball-state [--rate 100]]
Cases: {cyclone,fastdds}-{be,rel}-{640,960}; default all eight.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np
import rclpy
from ball_tracker_msgs.msg import BallState
from rclpy.qos import QoSProfile, qos_profile_sensor_data

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))
from harness import DDS_ENV, DomainLease, executable, ros_env  # noqa: E402

CYCLONE_PUBLISHER = ROOT / "test" / "integration" / "peers" / "cyclone_image_publisher.py"
RESOLUTIONS = {"640": (640, 480), "960": (960, 540)}
TRACKER_STAGES = ("transport_ms", "take_ms", "decode_ms", "total_ms", "publish_ms")

# rclpy/Fast DDS camera: same arguments and output as the Cyclone peer
FASTDDS_PUBLISHER = textwrap.dedent("""
    import json, sys, time, numpy as np, rclpy
    from rclpy.qos import QoSProfile, qos_profile_sensor_data
    from sensor_msgs.msg import Image
    frame, rate, count, reliable = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), sys.argv[4] == "reliable"
    rclpy.init()
    node = rclpy.create_node("camera_source")
    pub = node.create_publisher(Image, "/camera/image_raw", QoSProfile(depth=1) if reliable
                                else qos_profile_sensor_data)
    image = np.load(frame)
    msg = Image(height=image.shape[0], width=image.shape[1], encoding="bgr8", step=3 * image.shape[1])
    msg.header.frame_id = "camera"
    msg.data = image.tobytes()
    start = time.monotonic()
    while pub.get_subscription_count() == 0 and time.monotonic() - start < 20:
        time.sleep(0.05)
    time.sleep(0.5)
    period, next_t = 1.0 / rate, time.monotonic()
    for _ in range(count):
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), 1_000_000_000)
        pub.publish(msg)
        next_t += period
        time.sleep(max(0.0, next_t - time.monotonic()))
    time.sleep(0.5)
    print(json.dumps({"sent": count}), flush=True)
""")


def quantile(sorted_values: list, q: float) -> float:
    return sorted_values[min(len(sorted_values) - 1, int(q * len(sorted_values)))] if sorted_values else float("nan")


# -- 1. images through the tracker -------------------------------------------------------------
def image_case(case: str, seconds: float, rate: float, frame_dir: Path, dds_defaults: bool = False,
               tracker_params: tuple = (), realtime: int = 0, receiver_only: bool = False) -> dict:
    """One case: start the tracker and a publisher, count and time the answers.
    `dds_defaults`: both without the project's DDS settings (what they fix); `tracker_params`:
    "name:=value" overrides of config/ball_tracker.yaml; `realtime` > 0: the publisher and
    this receiving process run SCHED_FIFO at that priority (`receiver_only`: this process
    alone)."""
    from pal_statistics_msgs.msg import Statistics
    from rclpy.executors import SingleThreadedExecutor

    from ball_balance.vision.synthetic import SyntheticCamera, SyntheticScene

    vendor, reliability, size = case.split("-")
    width, height = RESOLUTIONS[size]
    frame = frame_dir / f"frame_{width}x{height}.npy"
    if not frame.exists():
        scene = SyntheticScene(SyntheticCamera(width=width, height=height))
        np.save(frame, scene.render((0.05, 0.03), noise_std=2.0)[0])
    count = int(rate * seconds)
    lease = DomainLease()
    env = ros_env(lease.domain_id)
    if dds_defaults:
        env.update({name: "" for name in DDS_ENV})
    # a real-time receiver's children would inherit its policy: the tracker starts normal
    # and takes its own (thread_priority)
    normal = ["chrt", "-o", "0"] if realtime > 0 else []
    tracker = subprocess.Popen([*normal, executable("ball_tracker"), "--ros-args", "--params-file",
                                str(ROOT / "config" / "ball_tracker.yaml"), "-p", "startup_frames:=3",
                                *(arg for param in tracker_params for arg in ("-p", param))],
                               env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True)
    context = rclpy.Context()
    rclpy.init(args=[], context=context, domain_id=lease.domain_id)  # not our options
    node = rclpy.create_node("transport_bench", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    latencies_ms, stages, skipped = [], {s: [] for s in TRACKER_STAGES}, {"stale": 0, "gaps": 0}
    received, tracker_values = {}, {}   # frame stamp ns -> (callback, DDS written, DDS received) / statistics

    def on_state(state, info):
        callback_ns = time.time_ns()
        stamp_ns = state.header.stamp.sec * 1_000_000_000 + state.header.stamp.nanosec
        latencies_ms.append((callback_ns - stamp_ns) / 1e6)
        received[round(stamp_ns / STAMP_KEY_NS)] = (stamp_ns, callback_ns, info["source_timestamp"],
                                                    info["received_timestamp"])

    def on_statistics(msg):
        values = {s.name: s.value for s in msg.statistics}
        for stage in TRACKER_STAGES:
            stages[stage].append(values.get(stage, float("nan")))
        skipped.update(stale=values.get("stale_frames", 0), gaps=values.get("skipped_frames", 0))
        if "stamp_s" in values:
            tracker_values[round(values["stamp_s"] * 1e9 / STAMP_KEY_NS)] = values

    node.create_subscription(BallState, "/ball_state", on_state, qos_profile_sensor_data)
    node.create_subscription(Statistics, "/ball_tracker/statistics/full", on_statistics, 100)
    deadline = time.monotonic() + 30
    while node.count_publishers("/ball_state") == 0 and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
    if realtime > 0 and not receiver_only:
        cmd = ["chrt", "-f", str(realtime)]
    else:
        cmd = []
    if vendor == "cyclone":
        cmd += [sys.executable, str(CYCLONE_PUBLISHER), str(frame), "--rate", str(rate), "--count", str(count)]
        cmd += ["--reliable"] if reliability == "rel" else []
    else:
        cmd += [sys.executable, "-c", FASTDDS_PUBLISHER, str(frame), str(rate), str(count),
               "reliable" if reliability == "rel" else "best_effort"]
    publisher = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, text=True)
    while publisher.poll() is None:
        executor.spin_once(timeout_sec=0.05)
    end = time.monotonic() + 1.0                # answers still in flight
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
    output = publisher.stdout.read().strip().splitlines()
    sent = json.loads(output[-1])["sent"] if output else 0
    executor.shutdown()
    node.destroy_node()
    context.try_shutdown()
    os.killpg(tracker.pid, 2)
    tracker.wait(timeout=10)
    lease.release()
    return {"sent": sent, "latencies_ms": sorted(latencies_ms), "stages": stages, "skipped": skipped,
            "chain": chain_stages(received, tracker_values)}


STAMP_KEY_NS = 100_000   # frames matched by stamp to 0.1 ms: the statistics carry it as float s (0.2 us steps)
CHAIN = ("camera write", "image transport", "tracker take", "track+publish", "state transport", "receiver take")


def chain_stages(received: dict, tracker_values: dict) -> list:
    """Per frame followed end to end: image stamp -> /ball_state callback here, split at the
    DDS samples' own wall-clock times (one host, one clock), ms: stamp -> image written (the
    publisher: conversion, serialisation, write), image write -> receipt in the tracker, ->
    its callback, -> /ball_state written (decode, track, /plate_pose and /ball_state
    publish), -> receipt here, -> callback here."""
    rows = []
    for key, (stamp_ns, callback_ns, written_ns, delivered_ns) in received.items():
        values = tracker_values.get(key)
        if values is None or "age_at_receipt_ms" not in values:
            continue
        at_tracker_ms = values["age_at_receipt_ms"]            # stamp -> tracker callback
        rows.append({"camera write": at_tracker_ms - values["take_ms"] - values["transport_ms"],
                     "image transport": values["transport_ms"], "tracker take": values["take_ms"],
                     "track+publish": (written_ns - stamp_ns) / 1e6 - at_tracker_ms,
                     "state transport": (delivered_ns - written_ns) / 1e6,
                     "receiver take": (callback_ns - delivered_ns) / 1e6,
                     "total": (callback_ns - stamp_ns) / 1e6})
    return rows


def print_chain(case: str, rows: list) -> None:
    """Median and p99 of each stage, and each stage's mean over the slowest 2 % of frames
    (where the tail comes from)."""
    if not rows:
        return
    slowest = sorted(rows, key=lambda r: r["total"])[-max(1, len(rows) // 50):]
    cells = []
    for stage in (*CHAIN, "total"):
        values = sorted(r[stage] for r in rows)
        cells.append(f"{stage} {quantile(values, 0.5):.2f}/{quantile(values, 0.99):.2f}/"
                     f"{np.mean([r[stage] for r in slowest]):.2f}")
    print(f"  {case}: per stage, median/p99/mean of the slowest 2 % ({len(rows)} frames), ms: " + ", ".join(cells))


def images(cases, seconds: float, rate: float, dds_defaults: bool, tracker_params: tuple = (),
           realtime: int = 0, receiver_only: bool = False) -> None:
    settings = "DDS defaults, without config/dds" if dds_defaults else "config/dds"
    settings += "".join(f", {param}" for param in tracker_params)
    if realtime > 0:
        from controller_manager_py.realtime import set_process_realtime_priority

        if not set_process_realtime_priority(realtime):   # rclpy's threads, started later, inherit it
            sys.exit("--realtime: SCHED_FIFO refused (needs CAP_SYS_NICE or an rtprio limit)")
        settings += f", {'receiver' if receiver_only else 'publisher and receiver'} SCHED_FIFO {realtime}"
    print(f"\n1. camera frames -> ball_tracker -> /ball_state in this process, {rate:.0f} Hz for {seconds:.0f} s "
          f"per case, {settings} (load average {os.getloadavg()[0]:.1f})")
    print(f"{'case':<18}{'answered':>16}{'median ms':>10}{'p95':>7}{'p99':>7}{'max':>7}{'stale':>6}{'gaps':>5}"
          f"   tracker stages, median ms: {' / '.join(s[:-3] for s in TRACKER_STAGES)}")
    chains = []
    with tempfile.TemporaryDirectory() as frame_dir:
        for case in cases:
            r = image_case(case, seconds, rate, Path(frame_dir), dds_defaults, tracker_params, realtime,
                           receiver_only)
            lat, sent = r["latencies_ms"], r["sent"]
            answered = f"{len(lat)}/{sent} ({100.0 * len(lat) / sent:.1f}%)" if sent else "publisher failed"
            medians = " / ".join(f"{np.nanmedian(r['stages'][s]):.2f}" if r["stages"][s] else "-"
                                 for s in TRACKER_STAGES)
            print(f"{case:<18}{answered:>16}{quantile(lat, 0.5):>10.2f}{quantile(lat, 0.95):>7.2f}"
                  f"{quantile(lat, 0.99):>7.2f}{(lat[-1] if lat else float('nan')):>7.2f}"
                  f"{r['skipped']['stale']:>6.0f}{r['skipped']['gaps']:>5.0f}   {medians}",
                  flush=True)
            chains.append((case, r["chain"]))
    for case, rows in chains:
        print_chain(case, rows)


# -- 2. BallState one hop --------------------------------------------------------------------
BALL_STATE_PUBLISHER = textwrap.dedent("""
    import sys, time, rclpy
    from ball_tracker_msgs.msg import BallState
    from rclpy.qos import QoSProfile, qos_profile_sensor_data
    rate, seconds, reliable = float(sys.argv[1]), float(sys.argv[2]), sys.argv[3] == "reliable"
    rclpy.init()
    node = rclpy.create_node("latency_source")
    pub = node.create_publisher(BallState, "/ball_state", QoSProfile(depth=10) if reliable else qos_profile_sensor_data)
    time.sleep(1.5)  # discovery
    msg = BallState(ball_found=True, tracking_valid=True, markers_found=4)
    period, next_t = 1.0 / rate, time.monotonic()
    for _ in range(int(rate * seconds)):
        now = time.time_ns()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 1_000_000_000)
        pub.publish(msg)
        next_t += period
        time.sleep(max(0.0, next_t - time.monotonic()))
    time.sleep(0.5)
""")


def ball_state_hop(rate: float, seconds: float, reliable: bool) -> list:
    lease = DomainLease()
    latencies_us = []

    def on_state(msg):
        sent = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        latencies_us.append((time.time_ns() - sent) / 1e3)

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=lease.domain_id)
    node = rclpy.create_node("latency_sink", context=context)
    node.create_subscription(BallState, "/ball_state", on_state,
                             QoSProfile(depth=10) if reliable else qos_profile_sensor_data)
    source = subprocess.Popen([sys.executable, "-c", BALL_STATE_PUBLISHER, str(rate), str(seconds),
                               "reliable" if reliable else "best_effort"], env=ros_env(lease.domain_id))
    while source.poll() is None:
        rclpy.spin_once(node, timeout_sec=0.1)
    node.destroy_node()
    context.try_shutdown()
    lease.release()
    return latencies_us


def ball_state(rate: float, seconds: float) -> None:
    expected = int(rate * seconds)
    print(f"\n2. BallState one hop, {rate:.0f} Hz for {seconds:.0f} s, two processes, loopback")
    print(f"{'QoS':<22}{'received':>10}{'median us':>11}{'p90 us':>9}{'p99 us':>9}{'max us':>9}")
    for reliable in (False, True):
        lat = sorted(ball_state_hop(rate, seconds, reliable))
        name = "reliable, depth 10" if reliable else "sensor data (BE, 5)"
        if not lat:
            print(f"{name:<22}{'0':>10}")
            continue
        print(f"{name:<22}{len(lat):>6}/{expected:<4}{statistics.median(lat):>10.0f}"
              f"{quantile(lat, 0.9):>9.0f}{quantile(lat, 0.99):>9.0f}{lat[-1]:>9.0f}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="per image case")
    parser.add_argument("--image-rate", type=float, default=60.0)
    parser.add_argument("--cases", default=",".join(f"{v}-{r}-{s}" for s in RESOLUTIONS for v in ("cyclone", "fastdds")
                                                    for r in ("be", "rel")))
    parser.add_argument("--no-images", action="store_true")
    parser.add_argument("--dds-defaults", action="store_true",
                        help="image cases without the project's DDS settings, for comparison")
    parser.add_argument("--tracker-param", action="append", default=[], metavar="NAME:=VALUE",
                        help="override a config/ball_tracker.yaml value (repeatable), e.g. thread_priority:=0")
    parser.add_argument("--realtime", type=int, default=0, metavar="PRIORITY",
                        help="the camera publisher and this receiving process run SCHED_FIFO at this priority, as "
                             "a real-time graph runs its camera driver and controller (0: normal scheduling)")
    parser.add_argument("--receiver-only", action="store_true",
                        help="with --realtime: only this receiving process (as the project's controllers run), the "
                             "camera publisher normally scheduled (a camera driver started without chrt)")
    parser.add_argument("--ball-state", action="store_true", help="also the BallState one-hop section")
    parser.add_argument("--rate", type=float, default=100.0, help="BallState rate")
    args = parser.parse_args()
    if not args.no_images:
        images([c for c in args.cases.split(",") if c], args.seconds, args.image_rate, args.dds_defaults,
               tuple(args.tracker_param), args.realtime, args.receiver_only)
    if args.ball_state:
        ball_state(args.rate, args.seconds)


if __name__ == "__main__":
    main()
