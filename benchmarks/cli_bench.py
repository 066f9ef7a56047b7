"""`ros2py topic echo` start-up time: process start -> first line printed, and -> exit (--once).

A BallState publisher (20 Hz, sensor-data QoS, like the tracker) runs on a private domain;
each run starts a fresh `ros2py topic echo /ball_state --once` and times its first stdout line.
Also timed: `ros2py -h` (interpreter + argparse only) and `import rclpy`, for the breakdown.

    source env.sh && python benchmarks/cli_bench.py [--runs 5]
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import textwrap
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))
from harness import DomainLease, executable, ros_env  # noqa: E402

PUBLISHER = textwrap.dedent("""
    import rclpy
    from ball_tracker_msgs.msg import BallState
    from rclpy.qos import qos_profile_sensor_data
    rclpy.init()
    node = rclpy.create_node('bench_ball_state')
    pub = node.create_publisher(BallState, '/ball_state', qos_profile_sensor_data)
    node.create_timer(0.05, lambda: pub.publish(BallState(x=0.1)))
    rclpy.spin(node)
""")


def time_first_line(cmd, env) -> tuple[float, float]:
    """(seconds to the first stdout line, seconds to exit)."""
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env, text=True)
    proc.stdout.readline()
    first = time.perf_counter() - start
    proc.stdout.read()
    proc.wait(timeout=60)
    return first, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args()
    lease = DomainLease()
    env = ros_env(lease.domain_id)
    ros2py = executable("ros2py")
    publisher = subprocess.Popen([sys.executable, "-c", PUBLISHER], env=env, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL)
    try:
        time_first_line([ros2py, "topic", "echo", "/ball_state", "--once"], env)  # warm caches
        cases = {
            "ros2py -h (interpreter + argparse)": [ros2py, "-h"],
            "python -c 'import rclpy'": [sys.executable, "-c", "import rclpy; print()"],
            "topic echo /ball_state --once": [ros2py, "topic", "echo", "/ball_state", "--once"],
            "topic echo /ball_state <type> --once": [ros2py, "topic", "echo", "/ball_state",
                                                     "ball_tracker_msgs/msg/BallState", "--once"],
        }
        print(f"ros2py start-up, {args.runs} runs each, {os.cpu_count()} CPUs, "
              f"load {os.getloadavg()[0]:.1f}")
        print(f"{'command':40s} {'first line median':>18s} {'min':>7s} {'max':>7s} {'runs > 1 s':>10s} "
              f"{'exit median':>12s}")
        for name, cmd in cases.items():
            samples = [time_first_line(cmd, env) for _ in range(args.runs)]
            firsts = [s[0] for s in samples]
            exits = [s[1] for s in samples]
            slow = sum(f > 1.0 for f in firsts)  # DDS discovery waiting for a periodic announcement
            print(f"{name:40s} {statistics.median(firsts):17.3f}s {min(firsts):6.3f}s {max(firsts):6.3f}s "
                  f"{slow:>4d} of {len(firsts):<3d} {statistics.median(exits):11.3f}s")
    finally:
        publisher.terminate()
        publisher.wait(timeout=10)
        lease.release()


if __name__ == "__main__":
    main()
