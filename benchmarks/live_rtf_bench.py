"""Real-time factor of the whole live simulated graph, as a user starts it.

Runs `scripts/sim_balance.sh` (simulated arm in ros2_control_node with the camera, ball_tracker,
the balance controller, visualizer and monitor, config/ files as shipped) on a private ROS domain,
with the camera at --width x --height and --rate Hz and --busy processes each keeping a core
busy. After --warmup-s (start-up, homing, engaging; wall time) it counts for --seconds:

  real-time factor     simulated seconds /clock advanced per wall second
  frames / sim s       camera frames published (/camera/camera_info) and answered on /ball_state
                       (distinct stamps) per simulated second
  ball dropped         whether /sim/ball_dropped said so

    python benchmarks/live_rtf_bench.py [--width 960 --height 540 --rate 60] [--seconds 20] [--busy 1]
        [--controller pid] [--sim-param NAME=VALUE ...]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))
from controller_manager_py.realtime import set_process_realtime_priority  # noqa: E402
from harness import DomainLease, Graph, ros_env, stop_groups  # noqa: E402

BUSY = "while True:\n    pass\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=60.0, help="camera rate (Hz of simulated time)")
    parser.add_argument("--width", type=int, default=960)
    parser.add_argument("--height", type=int, default=540)
    parser.add_argument("--seconds", type=float, default=20.0, help="measured wall time")
    parser.add_argument("--warmup-s", type=float, default=10.0, help="wall time after the first /ball_state")
    parser.add_argument("--busy", type=int, default=1, help="extra processes each keeping a core busy")
    parser.add_argument("--controller", default="pid", choices=("pid", "mpc", "policy"))
    parser.add_argument("--sim-param", action="append", default=[], metavar="NAME=VALUE",
                        help="a MujocoSystem parameter (repeatable), e.g. pacing=lockstep")
    parser.add_argument("--priority", type=int, default=10, help="SCHED_FIFO priority of this measuring process")
    args = parser.parse_args()

    from ball_tracker_msgs.msg import BallState
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import CameraInfo
    from std_msgs.msg import Bool

    lease = DomainLease()
    env = ros_env(lease.domain_id)
    sim_params = [f"camera_rate_hz={args.rate}", f"camera_width={args.width}", f"camera_height={args.height}",
                  *args.sim_param]
    command = [str(ROOT / "scripts" / "sim_balance.sh"), "--controller", args.controller]
    for param in sim_params:
        command += ["--sim-param", param]
    load_before = os.getloadavg()[0]
    graph = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                             start_new_session=True)
    busy = [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(args.busy)]
    graph_node = Graph(lease.domain_id, "live_rtf_bench")
    node = graph_node.node
    # SCHED_FIFO (below the graph's 19-45) for every thread, DDS receive threads too: normally
    # scheduled beside a busy process, this process lost samples and counted frames that were there
    if not set_process_realtime_priority(args.priority):
        print(f"(could not make this process SCHED_FIFO {args.priority}: frame counts may miss samples)")
    recording = False
    clocks, stamps, infos, dropped = [], set(), [], []

    def on_clock(msg):
        if recording:
            clocks.append((time.monotonic(), msg.clock.sec + msg.clock.nanosec * 1e-9))

    def on_state(msg):
        stamps.add((msg.header.stamp.sec, msg.header.stamp.nanosec, recording))

    node.create_subscription(Clock, "/clock", on_clock, QoSProfile(depth=1))
    node.create_subscription(CameraInfo, "/camera/camera_info", lambda m: infos.append(recording),
                             qos_profile_sensor_data)
    node.create_subscription(BallState, "/ball_state", on_state, qos_profile_sensor_data)
    node.create_subscription(Bool, "/sim/ball_dropped", lambda m: dropped.append(m.data),
                             QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                                        reliability=ReliabilityPolicy.RELIABLE))
    try:
        graph_node.wait_until(lambda: stamps or graph.poll() is not None, 180.0)  # start-up on a busy machine
        graph_node.spin_for(args.warmup_s)
        recording = True
        graph_node.spin_for(args.seconds)
        recording = False
        load = os.getloadavg()[0]
    finally:
        graph_node.close()
        for process in busy:
            process.kill()
        stop_groups([graph], grace_s=20.0)
        lease.release()
    print(f"scripts/sim_balance.sh --controller {args.controller}, camera {args.rate:.0f} Hz {args.width}x"
          f"{args.height}, {args.busy} busy process(es), {args.seconds:.0f} s; load average {load_before:.1f} "
          f"before, {load:.1f} at the end" + (f"; sim params {args.sim_param}" if args.sim_param else ""))
    if len(clocks) < 2:
        print("no /clock while measuring (did the graph start? run scripts/sim_balance.sh to see)")
        return 1
    sim_s, wall_s = clocks[-1][1] - clocks[0][1], clocks[-1][0] - clocks[0][0]
    frames = sum(1 for s in stamps if s[2])
    print(f"real-time factor {sim_s / wall_s:.2f} ({sim_s:.1f} simulated s in {wall_s:.1f} s); "
          f"per simulated s: camera frames published {sum(infos) / sim_s:.1f} (/camera/camera_info), answered on "
          f"/ball_state {frames / sim_s:.1f}; ball dropped: {bool(dropped and dropped[-1])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
