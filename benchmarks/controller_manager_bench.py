"""Controller manager timing on this machine: ros2_control_node with the mock UR arm.

Each case starts `ros2_control_node` (mock 6-joint system; joint_state_broadcaster, a
forward position controller on three joints and the joint trajectory controller on the
other three, all active) on a private ROS domain, drives it (forward commands at 100 Hz,
a 3-waypoint trajectory every 0.5 s), optionally subscribes to ~/statistics and
~/introspection_data and calls ~/list_controllers every 100 ms, then reads the manager's
own statistics at the start and end of a measuring window and reports the window:
achieved rate, periodicity mean error and standard deviation (Hz), cycle execution time
(read + update + write) mean and standard deviation (us). A second table gives the cost
of the statistics themselves, measured in-process.

    source env.sh && python benchmarks/controller_manager_bench.py [--seconds 4]
"""
from __future__ import annotations

import argparse
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))

from harness import DomainLease, executable, ros_env  # noqa: E402

JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
          "wrist_3_joint"]
HOME = [0.0, -1.5707963267948966, 1.5707963267948966, -1.5707963267948966, 1.5707963267948966, 0.0]
PARAMS = """controller_manager:
  ros__parameters:
    update_rate: {rate}
    diagnostics.period: 1000.0
    joint_state_broadcaster: {{type: joint_state_broadcaster/JointStateBroadcaster}}
    forward_position_controller: {{type: position_controllers/JointGroupPositionController}}
    scaled_joint_trajectory_controller: {{type: joint_trajectory_controller/JointTrajectoryController}}
    activate_controllers: [joint_state_broadcaster, forward_position_controller, scaled_joint_trajectory_controller]
forward_position_controller:
  ros__parameters: {{joints: {first}}}
scaled_joint_trajectory_controller:
  ros__parameters:
    joints: {second}
    speed_scaling_interface_name: speed_scaling/speed_scaling_factor
"""


def window(a: dict, b: dict, prefix: str):
    """Mean and standard deviation of the samples added between snapshots a and b."""
    na, nb = a[f"{prefix}/sample_count"], b[f"{prefix}/sample_count"]
    n = nb - na
    if n <= 1:
        return math.nan, math.nan, n

    def sums(s, count):
        mean, std = s[f"{prefix}/average"], s[f"{prefix}/standard_deviation"]
        return count * mean, count * (std * std + mean * mean)
    s1a, s2a = sums(a, na) if na else (0.0, 0.0)
    s1b, s2b = sums(b, nb)
    mean = (s1b - s1a) / n
    return mean, math.sqrt(max(0.0, (s2b - s2a) / n - mean * mean)), n


class Driver:
    def __init__(self, domain: int):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node("bench_driver", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.01)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


def run_case(rate: int, list_calls: bool, subscribe: bool, seconds: float) -> dict:
    from controller_manager_msgs.srv import ListControllers
    from pal_statistics_msgs.msg import Statistics, StatisticsNames, StatisticsValues
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from std_msgs.msg import Float64MultiArray
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    lease = DomainLease()
    tmp = Path(tempfile.mkdtemp(prefix="cm_bench_"))
    params = tmp / "params.yaml"
    params.write_text(PARAMS.format(rate=rate, first=JOINTS[:3], second=JOINTS[3:]))
    log = open(tmp / "node.log", "wb")
    process = subprocess.Popen([executable("ros2_control_node"), "--ros-args", "--params-file", str(params),
                                "-p", f"robot_description_file:={ROOT / 'config' / 'mock_ur.urdf'}"],
                               stdout=log, stderr=subprocess.STDOUT, env=ros_env(lease.domain_id),
                               start_new_session=True)
    driver = Driver(lease.domain_id)
    node = driver.node
    try:
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        names = {}
        node.create_subscription(StatisticsNames, "/controller_manager/statistics/names",
                                 lambda m: names.update(v=m), latched)
        kept = []
        if subscribe:
            for topic in ("statistics", "introspection_data"):
                kept.append(node.create_subscription(Statistics, f"/controller_manager/{topic}/full",
                                                     lambda m: None, 10))
                kept.append(node.create_subscription(StatisticsValues, f"/controller_manager/{topic}/values",
                                                     lambda m: None, 10))
        forward = node.create_publisher(Float64MultiArray, "/forward_position_controller/commands", 10)
        trajectory = node.create_publisher(JointTrajectory, "/scaled_joint_trajectory_controller/joint_trajectory",
                                           10)
        client = node.create_client(ListControllers, "/controller_manager/list_controllers")
        deadline = time.monotonic() + 30
        while not client.service_is_ready() and time.monotonic() < deadline:
            driver.spin_for(0.1)
        tick = {"k": 0, "calls": 0}

        def on_command_timer():
            k = tick["k"] = tick["k"] + 1
            forward.publish(Float64MultiArray(data=[HOME[i] + 0.05 * math.sin(0.02 * k) for i in range(3)]))
            if k % 50 == 0:
                msg = JointTrajectory(joint_names=JOINTS[3:])
                for n, t in enumerate((0.3, 0.6, 1.0)):
                    point = JointTrajectoryPoint(positions=[HOME[3 + i] + 0.05 * (-1) ** (n + k // 50)
                                                            for i in range(3)])
                    point.time_from_start.nanosec = int(t * 1e9) % 1_000_000_000
                    point.time_from_start.sec = int(t)
                    msg.points.append(point)
                trajectory.publish(msg)
            if list_calls and k % 10 == 0:
                client.call_async(ListControllers.Request())
                tick["calls"] += 1
        node.create_timer(0.01, on_command_timer)

        def snapshot():
            got = []
            sub = node.create_subscription(StatisticsValues, "/controller_manager/statistics/values", got.append, 10)
            end = time.monotonic() + 10
            while (not got or "v" not in names or got[-1].names_version != names["v"].names_version) \
                    and time.monotonic() < end:
                driver.executor.spin_once(timeout_sec=0.01)
            node.destroy_subscription(sub)
            if not got:
                raise RuntimeError(f"no statistics from the node (log: {tmp / 'node.log'})")
            return dict(zip(names["v"].names, got[-1].values)), time.monotonic()

        driver.spin_for(2.0)  # warm-up: start-up transients stay out of the window
        a, ta = snapshot()
        driver.spin_for(seconds)
        b, tb = snapshot()
        m = "controller_manager.stats"
        period_mean, period_std, n = window(a, b, f"{m}/periodicity")
        exec_mean, exec_std, _ = window(a, b, f"{m}/total_time")
        return dict(rate=rate, achieved=n / (tb - ta), mean_error=abs(period_mean - rate), period_std=period_std,
                    exec_mean=exec_mean, exec_std=exec_std, list_calls=tick["calls"], subscribe=subscribe,
                    skipped=b[f"{m}/skipped_periods"] - a[f"{m}/skipped_periods"])
    finally:
        driver.close()
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
        log.close()
        lease.release()


def statistics_cost() -> list:
    """In-process: cost of the per-cycle statistics updates and of one registry publish."""
    import rclpy
    from pal_statistics_msgs.msg import Statistics, StatisticsValues

    from controller_manager_py.manager.controller_manager import ControllerManager
    from controller_manager_py.manager.introspection import introspection_entries, statistics_entries
    from controller_manager_py.manager.statistics import PeriodicityStats, Stats
    from controller_manager_py.ros.statistics_publisher import StatisticsRegistry

    rows = []
    p = PeriodicityStats()
    n = 200_000
    t0 = time.perf_counter()
    for k in range(n):
        p.add(k * 0.002, k * 0.002 + 1e-4)
    per_periodic = (time.perf_counter() - t0) / n
    s = Stats()
    t0 = time.perf_counter()
    for k in range(n):
        s.add(k * 1e-3)
    per_stats = (time.perf_counter() - t0) / n
    cm = ControllerManager(500)
    cm.load_robot_description((ROOT / "config" / "mock_ur.urdf").read_text())
    for name, type_name, params in (
            ("jsb", "joint_state_broadcaster/JointStateBroadcaster", {}),
            ("fwd", "position_controllers/JointGroupPositionController", {"joints": JOINTS[:3]}),
            ("jtc", "joint_trajectory_controller/JointTrajectoryController", {"joints": JOINTS[3:]})):
        cm.load_controller(name, type_name, params)
        cm.configure_controller(name)
    cm.switch_controller(["jsb", "fwd", "jtc"], [])
    # per cycle: loop periodicity, 3 controllers, read + write of one component (PeriodicityStats),
    # and the manager's read/update/write times (Stats)
    per_cycle = 6 * per_periodic + 3 * per_stats
    rows.append(("statistics updates in the loop, per cycle (always on, 3 ctrl + 1 hw)", per_cycle * 1e6))
    context, lease = rclpy.Context(), DomainLease()
    rclpy.init(context=context, domain_id=lease.domain_id)
    node = rclpy.create_node("stats_cost", context=context)
    try:
        for label, entries_fn in (("statistics", statistics_entries), ("introspection_data", introspection_entries)):
            registry = StatisticsRegistry(node, f"~/{label}")
            entries = entries_fn(cm)
            registry.set_entries(entries)
            reps = 2000
            t0 = time.perf_counter()
            for _ in range(reps):
                registry.publish()
            idle = (time.perf_counter() - t0) / reps
            rows.append((f"~/{label} publish, no subscribers ({len(entries)} entries), per publish", idle * 1e6))
            subs = [node.create_subscription(StatisticsValues, f"~/{label}/values", lambda m: None, 10)]
            for what in ("values subscribed", "values + full subscribed"):
                t0 = time.perf_counter()
                for _ in range(reps // 4):
                    registry.publish()
                busy = (time.perf_counter() - t0) / (reps // 4)
                rows.append((f"~/{label} publish, {what}, per publish", busy * 1e6))
                rows.append(("  -> amortised per 500 Hz cycle at 20 Hz (loop idle time)", busy * 20 / 500 * 1e6))
                subs.append(node.create_subscription(Statistics, f"~/{label}/full", lambda m: None, 10))
            for sub in subs:
                node.destroy_subscription(sub)
    finally:
        node.destroy_node()
        context.try_shutdown()
        lease.release()
        cm.shutdown()
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=4.0, help="measuring window per case")
    args = parser.parse_args()
    cases = [(100, True, True), (500, True, True), (1000, True, True), (500, False, False), (500, True, False)]
    print(f"{'rate':>6} {'list/100ms':>10} {'stats subs':>10} {'achieved Hz':>11} {'period mean err Hz':>18} "
          f"{'period std Hz':>13} {'exec mean us':>12} {'exec std us':>11} {'skipped':>7}")
    for rate, list_calls, subscribe in cases:
        r = run_case(rate, list_calls, subscribe, args.seconds)
        print(f"{rate:>6} {'yes' if list_calls else 'no':>10} {'yes' if subscribe else 'no':>10} "
              f"{r['achieved']:>11.1f} {r['mean_error']:>18.2f} {r['period_std']:>13.2f} {r['exec_mean']:>12.1f} "
              f"{r['exec_std']:>11.1f} {int(r['skipped']):>7}", flush=True)
    print()
    print(f"{'statistics cost (in-process)':<72} {'us':>8}")
    for label, us in statistics_cost():
        print(f"{label:<72} {us:>8.2f}")


if __name__ == "__main__":
    main()
