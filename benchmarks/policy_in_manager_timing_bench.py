"""Controller manager timing at 500 Hz with the ball balance policy controller active.

Each case starts `ros2_control_node` on a private ROS domain with the mock UR arm carrying
the plate (ball_balance.robot.robot_description("mock")), joint_state_broadcaster and the
case's controller, while this process publishes a ball moving on the plate to /ball_state at
60 Hz (wall-clock stamps, as a camera would) and `--busy` other processes each keep a core
busy. Cases:

  forward_position_controller   the node path's controller in the manager, fed at 60 Hz (baseline)
  ball_balance_controller       config/ur_controllers_policy.yaml: the policy engaged, each step in
                                the controller's worker thread (async_step, SCHED_FIFO 45, on the
                                loop's CPU), targets written every cycle
  same, worker on any CPU       step_thread_on_loop_cpu: false
  same, worker normal priority  step_thread_priority: 0
  same, async_step: false       the step inline in the loop's update()
  same, former loop defaults    the manager's switch interval 20 us and no held sleep before the
                                spin (gil_switch_interval, wake_tail: manager/loop.py says why not)
  same, held sleep 200 us       wake_tail 200 us instead of the default 300 us

The table is controller_manager_bench.py's (the node's cycle log, cycles that started in the
window): periodicity std (Hz, ros2_control WARN above 5 Hz), execution time mean/std (us,
WARN above a std of 100 us), the longest period and the periods over 1.5x / 2x nominal;
beside it what the policy controller reported on ~/introspection_data at the end (mode,
missed steps) and its step time in the window (median and max of the values it published at
20 Hz); with `--witness`, which late cycles the machine shared.

    source env.sh && python benchmarks/policy_in_manager_timing_bench.py [--seconds 8] [--busy 1] [--cases 0,1] \
        [--witness]
"""
from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from controller_manager_bench import HEADER, Busy, Driver, row, run_manager, timing  # noqa: E402

from ball_balance.robot import HOME_POSITIONS_RAD, JOINT_NAMES, robot_description  # noqa: E402

POLICY = "ball_balance_controller"
# label, controller, its parameter overrides, the manager's
CASES = [
    ("forward_position_controller (node path)", "forward_position_controller", {}, {}),
    ("ball_balance_controller, async_step", POLICY, {}, {}),
    ("same, worker on any CPU", POLICY, {"step_thread_on_loop_cpu": False}, {}),
    ("same, worker at normal priority", POLICY, {"step_thread_priority": 0}, {}),
    ("ball_balance_controller, step inline", POLICY, {"async_step": False}, {}),
    ("same as async_step, former loop defaults", POLICY, {}, {"loop.gil_switch_interval": 2e-5, "loop.wake_tail": 0.0}),
    ("same as async_step, held sleep 200 us", POLICY, {}, {"loop.wake_tail": 2e-4}),
]


def params_file(controller: str, overrides: dict, manager_overrides: dict) -> dict:
    policy = yaml.safe_load((ROOT / "config" / "ur_controllers_policy.yaml").read_text())[POLICY]
    policy["ros__parameters"].update(overrides)
    return {
        "controller_manager": {"ros__parameters": {
            **manager_overrides,
            "update_rate": 500, "diagnostics.period": 1.0,
            "joint_state_broadcaster": {"type": "joint_state_broadcaster/JointStateBroadcaster"},
            "forward_position_controller": {"type": "position_controllers/JointGroupPositionController"},
            POLICY: {"type": "ball_balance_controllers/BallBalanceController"},
            "activate_controllers": ["joint_state_broadcaster", controller]}},
        "forward_position_controller": {"ros__parameters": {"joints": list(JOINT_NAMES)}},
        POLICY: policy,
    }


def drive(driver: Driver, controller: str, seconds: float) -> tuple:
    """Ball states at 60 Hz (and forward commands at 60 Hz, the nodes' rate, for the baseline); 3 s warm-up (the
    policy homes, sees the ball and engages), then `seconds`. Returns the window and the policy
    controller's last introspection values, with "step_samples": its step time (us) as
    published (20 Hz, the last step's) during the window."""
    from ball_tracker_msgs.msg import BallState
    from pal_statistics_msgs.msg import Statistics
    from rclpy.qos import qos_profile_sensor_data
    from std_msgs.msg import Float64MultiArray

    node = driver.node
    balls = node.create_publisher(BallState, "/ball_state", qos_profile_sensor_data)
    forward = node.create_publisher(Float64MultiArray, "/forward_position_controller/commands", 10)
    seen = {}
    step_samples = []
    measuring = False

    def on_introspection(msg):
        for item in msg.statistics:
            if item.name.startswith(POLICY + "."):
                seen[item.name[len(POLICY) + 1:]] = item.value
                if measuring and item.name == POLICY + ".step_time_us":
                    step_samples.append(item.value)
    node.create_subscription(Statistics, "/controller_manager/introspection_data/full", on_introspection, 10)
    driver.list_controllers_client(timeout_s=90)   # waits until the manager answers
    t0 = time.time()

    def on_ball_timer():
        t = time.time()
        a = 0.8 * (t - t0)
        msg = BallState(x=0.05 * math.cos(a), y=0.05 * math.sin(a), vx=-0.04 * math.sin(a), vy=0.04 * math.cos(a),
                        ball_found=True, tracking_valid=True, markers_found=4)
        msg.header.stamp.sec, msg.header.stamp.nanosec = int(t), int((t % 1.0) * 1e9)
        msg.header.frame_id = "plate_center"
        balls.publish(msg)

    def on_forward_timer():
        a = 0.8 * (time.time() - t0)
        forward.publish(Float64MultiArray(data=[q + 0.02 * math.sin(a + i) for i, q in enumerate(HOME_POSITIONS_RAD)]))
    node.create_timer(1.0 / 60.0, on_ball_timer)
    if controller == "forward_position_controller":
        node.create_timer(1.0 / 60.0, on_forward_timer)
    driver.spin_for(3.0)
    start = time.monotonic()
    measuring = True
    driver.spin_for(seconds)
    return (start, time.monotonic()), {**seen, "step_samples": step_samples}


def run_case(controller: str, overrides: dict, manager_overrides: dict, seconds: float, witness: bool) -> tuple:
    urdf = Path(tempfile.mkdtemp(prefix="policy_cm_bench_")) / "robot.urdf"
    urdf.write_text(robot_description("mock"))
    data, window, seen = run_manager(yaml.safe_dump(params_file(controller, overrides, manager_overrides)),
                                     {"robot_description_file": str(urdf)},
                                     lambda driver: drive(driver, controller, seconds), witness)
    return timing(data, *window), seen


MODES = {0.0: "homing", 1.0: "ready", 2.0: "engaged", 3.0: "holding", 4.0: "returning"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=8.0, help="measuring window per case")
    parser.add_argument("--busy", type=int, default=1, help="busy processes beside the manager")
    parser.add_argument("--cases", default="", help="comma-separated case numbers (0-based, table order); "
                        "default all")
    parser.add_argument("--repeat", type=int, default=1, help="run the chosen cases this many times, interleaved")
    parser.add_argument("--witness", action="store_true", help="a machine witness beside each case (as "
                        "controller_manager_bench.py's): which late cycles the kernel or the hypervisor caused")
    args = parser.parse_args()
    chosen = [CASES[int(i)] for i in args.cases.split(",")] if args.cases else CASES
    print(f"load average at start: {os.getloadavg()[0]:.2f}; {os.cpu_count()} CPUs; window {args.seconds:g} s; "
          f"{args.busy} busy process(es)")
    print(f"{HEADER} | policy: mode, missed steps, step us median / max")
    with Busy(args.busy):
        for label, controller, overrides, manager_overrides in chosen * args.repeat:
            result, seen = run_case(controller, overrides, manager_overrides, args.seconds, args.witness)
            policy = ""
            if controller == POLICY:
                mode = MODES.get(seen.get("mode"), seen.get("mode"))
                steps = seen["step_samples"] or [math.nan]
                policy = (f" | {mode}, {seen.get('missed_steps', math.nan):.0f}, "
                          f"{statistics.median(steps):.0f} / {max(steps):.0f}")
            print(row(label, 500, result) + policy, flush=True)
    print(f"load average at end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
