"""BallState one-hop latency between two processes (rclpy + Fast DDS, loopback).

A publisher process sends BallState at RATE Hz with the send time in header.stamp; this
process receives it and records (receive time - send time). Both use the same clock
(CLOCK_REALTIME on one machine). Prints median/p90/p99/max for sensor-data QoS (what the
tracker uses) and reliable QoS.

usage: python benchmarks/transport_bench.py [--rate 100] [--seconds 20]
"""
import argparse
import os
import statistics
import subprocess
import sys
import textwrap
import time

import rclpy
from ball_tracker_msgs.msg import BallState
from rclpy.qos import QoSProfile, qos_profile_sensor_data

PUBLISHER = textwrap.dedent("""
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


def measure(rate: float, seconds: float, reliable: bool) -> list:
    latencies_us = []

    def on_state(msg):
        sent = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        latencies_us.append((time.time_ns() - sent) / 1e3)

    node = rclpy.create_node("latency_sink")
    node.create_subscription(BallState, "/ball_state", on_state,
                             QoSProfile(depth=10) if reliable else qos_profile_sensor_data)
    source = subprocess.Popen([sys.executable, "-c", PUBLISHER, str(rate), str(seconds),
                               "reliable" if reliable else "best_effort"])
    while source.poll() is None:
        rclpy.spin_once(node, timeout_sec=0.1)
    node.destroy_node()
    return latencies_us


def quantile(sorted_values: list, q: float) -> float:
    return sorted_values[min(len(sorted_values) - 1, int(q * len(sorted_values)))]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--seconds", type=float, default=20.0)
    args = parser.parse_args()
    os.environ.setdefault("ROS_DOMAIN_ID", "97")
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    rclpy.init()
    expected = int(args.rate * args.seconds)
    print(f"BallState one-hop latency, {args.rate:.0f} Hz for {args.seconds:.0f} s, two processes, loopback")
    print(f"{'QoS':<22}{'received':>10}{'median us':>11}{'p90 us':>9}{'p99 us':>9}{'max us':>9}")
    for reliable in (False, True):
        lat = sorted(measure(args.rate, args.seconds, reliable))
        if not lat:
            print(f"{'reliable' if reliable else 'sensor data (BE)':<22}{'0':>10}")
            continue
        name = "reliable, depth 10" if reliable else "sensor data (BE, 5)"
        print(f"{name:<22}{len(lat):>6}/{expected:<4}{statistics.median(lat):>10.0f}"
              f"{quantile(lat, 0.9):>9.0f}{quantile(lat, 0.99):>9.0f}{lat[-1]:>9.0f}")
    rclpy.shutdown()


if __name__ == "__main__":
    main()
