"""Controller manager timing on this machine: ros2_control_node with the mock UR arm.

Each case starts `ros2_control_node` (mock 6-joint system; joint_state_broadcaster, a
forward position controller on three joints and the joint trajectory controller on the
other three, all active) on a private ROS domain, drives it (forward commands at 100 Hz,
a 3-waypoint trajectory every 0.5 s), optionally subscribes to ~/statistics and
~/introspection_data and calls ~/list_controllers every 100 ms, while `--busy` other
processes each keep a core busy. The node keeps a log of every cycle (deadline, start,
end: `cycle_log_file`), written when it stops (SIGINT, as Ctrl-C); the table is computed
from the cycles that started inside the measuring window:

  periodicity std   standard deviation of 1/period (Hz), ros2_control's WARN line at 5 Hz;
                    period = time between two cycle starts, as ros2_control takes it (the
                    time between update() calls) and as the manager's own statistics do
  exec mean/std     read + update + write time (us); WARN at a std of 100 us
  max period        the longest gap between two cycle starts (ms)
  >1.5x, >2x        periods longer than 1.5 and 2 times nominal
  p99 period        99th percentile of the period (ms)
  late p50/p99      how long after its deadline a cycle started (us): wake-up + interpreter lock
  targets           yes when periodicity std <= 5 Hz, exec std <= 100 us and no period > 2x
  rel/held p99      99th percentile of how late the lock-releasing sleep returned (kernel
                    wake-up + waiting for the interpreter lock) and the lock-holding sleep
                    (kernel wake-up alone), us
  late>T/2          cycles that started over half a period after their deadline (1 ms at
    (machine)       500 Hz); in brackets how many of them were the machine's: the loop's held
                    sleep (`wake_tail`: the interpreter lock held, so no Python thread in the
                    way) itself came back over half a period late; or its lock-releasing
                    sleep did, and the loop took the lock straight back (one voluntary
                    context switch in the cycle log: no wait for the lock); or, with
                    `--witness`, a witness thread in C (benchmarks/native/wakeup_baseline.c,
                    SCHED_FIFO 10 above the loop, on its CPU, waking every 0.937 ms) woke
                    over 0.5 ms late between that cycle's deadline and its start, so the CPU
                    was taken from both by the kernel or the hypervisor. The witness sees a
                    stall only when one of its deadlines falls in it, so it misses many short
                    ones, and at 1 kHz its own wake-ups delay the loop; the sleeps see those
                    that end them. The rest is the manager's own (its process, its
                    interpreter) or a stall all missed. The kernel here does not preempt a
                    system call (`Dynamic Preempt: none`), so "the kernel" includes a
                    lower-priority thread's system call, the manager's own ones too

The acceptance table ends with the machine's own limit at 1 kHz: the same wait without Python
(benchmarks/native/wakeup_baseline.c, compiled with the system's C compiler: SCHED_FIFO at the
loop's default priority, on the loop's CPU, a sleep to the manager's default spin tail before
each deadline and a busy wait after it, the loop's schedule). Whatever it shows beyond the
targets is the kernel's and the machine's (wake-up latency, a virtual CPU taken away), and no
Python loop can do better; its rel p99 column is how late its sleep returned.

Tables:
  acceptance   500 Hz with `--busy` busy processes, 1 kHz with none (the targets)
  causes       one knob changed at a time against the defaults, at 500 Hz under load, cases
               interleaved over `--rounds` so a change in the machine's load hits all alike
  tails        how the loop waits for its deadline (held lock, busy wait), at 500 Hz under
               load and 1 kHz without, interleaved over `--rounds` (the held sleep is at most
               a fifth of a period: 200 us at 1 kHz, manager/loop.py)
  cost         the statistics' own cost, in-process

    source env.sh && python benchmarks/controller_manager_bench.py [--table causes] [--seconds 5] [--busy 1] [--witness]
"""
from __future__ import annotations

import argparse
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))

from harness import DomainLease, Graph, executable, ros_env, stop_groups  # noqa: E402

JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
          "wrist_3_joint"]
HOME = [0.0, -1.5707963267948966, 1.5707963267948966, -1.5707963267948966, 1.5707963267948966, 0.0]
PARAMS = """controller_manager:
  ros__parameters:
    update_rate: {rate}
    diagnostics.period: 1.0
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
LATE_PERIODS = 0.5              # a cycle starting this many periods late is counted (1 ms at 500 Hz)
# Not a divisor or multiple of a loop period: a witness waking on the loop's own grid took the
# CPU in the same microseconds before every deadline, and the loop's schedule (which moves after
# a start later than 2 % of a period) locked onto it at 1 kHz: every cycle started about 20 us
# late (median 22 us against 1 us without the witness). Drifting by 63 us a millisecond, it
# meets the last microseconds before a deadline now and then instead.
WITNESS_PERIOD_S = 0.937e-3
WITNESS_LATE_S = 0.5e-3
WITNESS_PRIORITY_ABOVE_LOOP = 10

# Python's own defaults: what a plain rclpy loop thread gets
PLAIN = {"thread_priority": 0, "loop.executor_thread_priority": 0, "loop.gil_switch_interval": 0.005,
         "loop.gc_mode": "automatic", "loop.wake_tail": 0.0, "loop.spin_tail": 0.0, "loop.hold_interpreter": False,
         "loop.executor_on_loop_cpu": False}
CAUSES = [
    ("plain Python thread (no RT knob)", PLAIN, True),
    ("+ SCHED_FIFO loop 50 / executor 40", {**PLAIN, "thread_priority": 50, "loop.executor_thread_priority": 40}, True),
    ("+ switch interval 100 us", {**PLAIN, "thread_priority": 50, "loop.executor_thread_priority": 40,
                                  "loop.gil_switch_interval": 1e-4}, True),
    ("+ gc in the loop's slack", {**PLAIN, "thread_priority": 50, "loop.executor_thread_priority": 40,
                                  "loop.gil_switch_interval": 1e-4, "loop.gc_mode": "idle"}, True),
    ("+ interpreter held through the cycle", {**PLAIN, "thread_priority": 50, "loop.executor_thread_priority": 40,
                                              "loop.gil_switch_interval": 1e-4, "loop.gc_mode": "idle",
                                              "loop.hold_interpreter": True}, True),
    ("+ spin tail 100 us", {"loop.executor_on_loop_cpu": False, "loop.wake_tail": 0.0}, True),
    ("+ executor on the loop's CPU", {"loop.wake_tail": 0.0}, True),
    ("+ held sleep 300 us before the spin (defaults)", {}, True),
    ("defaults, held sleep 200 us", {"loop.wake_tail": 2e-4}, True),
    ("defaults, switch interval 20 us", {"loop.gil_switch_interval": 2e-5}, True),
    ("defaults, interpreter not held in the cycle", {"loop.hold_interpreter": False}, True),
    ("defaults, executor normal priority", {"loop.executor_thread_priority": 0}, True),
    ("defaults, gc automatic", {"loop.gc_mode": "automatic"}, True),
    ("defaults, no spin", {"loop.spin_tail": 0.0}, True),
    ("defaults, statistics not subscribed", {}, False),
]

TAILS = [
    ("no tail", {"loop.wake_tail": 0.0, "loop.spin_tail": 0.0}),
    ("spin 100 us", {"loop.wake_tail": 0.0}),
    ("spin 200 us", {"loop.wake_tail": 0.0, "loop.spin_tail": 2e-4}),
    ("held 300 + spin 100 us (defaults)", {}),
    ("held 200 + spin 100 us", {"loop.wake_tail": 2e-4}),
    ("held 200 + spin 100 us, switch 20 us", {"loop.wake_tail": 2e-4, "loop.gil_switch_interval": 2e-5}),
    ("spin 100 us, switch 20 us (former defaults)", {"loop.wake_tail": 0.0, "loop.gil_switch_interval": 2e-5}),
]


class Driver(Graph):
    """The benchmark's own node: commands, list_controllers calls, statistics subscriptions."""

    def __init__(self, domain: int):
        super().__init__(domain, "bench_driver")

    def list_controllers_client(self, timeout_s: float):
        """A client of the manager's list_controllers, once the manager is up (it answers)."""
        from controller_manager_msgs.srv import ListControllers

        client = self.node.create_client(ListControllers, "/controller_manager/list_controllers")
        if not self.wait_until(client.service_is_ready, timeout_s):
            raise RuntimeError(f"the manager did not come up within {timeout_s:.0f} s")
        return client


def drive(driver: Driver, list_calls: bool, subscribe: bool, seconds: float) -> tuple:
    """Wait for the manager, load it for a 2 s warm-up and `seconds`; returns the window."""
    from controller_manager_msgs.srv import ListControllers
    from pal_statistics_msgs.msg import Statistics, StatisticsValues
    from std_msgs.msg import Float64MultiArray
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    node = driver.node
    if subscribe:
        for topic in ("statistics", "introspection_data"):
            node.create_subscription(Statistics, f"/controller_manager/{topic}/full", lambda m: None, 10)
            node.create_subscription(StatisticsValues, f"/controller_manager/{topic}/values", lambda m: None, 10)
    forward = node.create_publisher(Float64MultiArray, "/forward_position_controller/commands", 10)
    trajectory = node.create_publisher(JointTrajectory, "/scaled_joint_trajectory_controller/joint_trajectory", 10)
    client = driver.list_controllers_client(timeout_s=60)
    tick = {"k": 0}

    def on_command_timer():
        k = tick["k"] = tick["k"] + 1
        forward.publish(Float64MultiArray(data=[HOME[i] + 0.05 * math.sin(0.02 * k) for i in range(3)]))
        if k % 50 == 0:
            msg = JointTrajectory(joint_names=JOINTS[3:])
            for n, t in enumerate((0.3, 0.6, 1.0)):
                point = JointTrajectoryPoint(positions=[HOME[3 + i] + 0.05 * (-1) ** (n + k // 50)
                                                        for i in range(3)])
                point.time_from_start.sec, point.time_from_start.nanosec = int(t), int(t % 1 * 1e9)
                msg.points.append(point)
            trajectory.publish(msg)
        if list_calls and k % 10 == 0:
            client.call_async(ListControllers.Request())
    node.create_timer(0.01, on_command_timer)
    driver.spin_for(2.0)  # warm-up: start-up transients stay out of the window
    start = time.monotonic()
    driver.spin_for(seconds)
    return start, time.monotonic()


def run_manager(params_yaml: str, overrides: dict, drive_with, witness: bool = False) -> tuple:
    """Start ros2_control_node with params_yaml (+ `-p` overrides) and a cycle log, call
    drive_with(driver) -> (window, result), stop the node; (cycle log data, window, result).
    witness: a MachineWitness runs beside the node; its log joins the data."""
    machine = MachineWitness() if witness else None     # (built first: a failed build leaks nothing)
    lease = DomainLease()
    tmp = Path(tempfile.mkdtemp(prefix="cm_bench_"))
    (tmp / "params.yaml").write_text(params_yaml)
    cycle_log = tmp / "cycles.npz"
    arguments = []
    for key, value in {**overrides, "loop.cycle_log_file": str(cycle_log)}.items():
        arguments += ["-p", f"{key}:={value}"]
    log = open(tmp / "node.log", "wb")
    if machine is not None:
        machine.start()
    process = subprocess.Popen([executable("ros2_control_node"), "--ros-args", "--params-file",
                                str(tmp / "params.yaml"), *arguments],
                               stdout=log, stderr=subprocess.STDOUT, env=ros_env(lease.domain_id),
                               start_new_session=True)
    driver = Driver(lease.domain_id)
    try:
        window, result = drive_with(driver)
    finally:
        driver.close()
        stop_groups([process], grace_s=20.0)  # a clean stop (Ctrl-C) writes the cycle log
        log.close()
        lease.release()
        witness_log = machine.stop() if machine is not None else {}
    if not cycle_log.exists():
        raise RuntimeError(f"no cycle log (node log: {tmp / 'node.log'})")
    return {**np.load(cycle_log), **witness_log}, window, result


def run_case(rate: int, params: dict, subscribe: bool, seconds: float, list_calls: bool = True,
             witness: bool = False) -> dict:
    data, window, _ = run_manager(
        PARAMS.format(rate=rate, first=JOINTS[:3], second=JOINTS[3:]),
        {**params, "robot_description_file": str(ROOT / "config" / "mock_ur.urdf")},
        lambda driver: (drive(driver, list_calls, subscribe, seconds), None), witness)
    return timing(data, *window)


def timing(data, t0: float, t1: float) -> dict:
    """The table's figures from a cycle log, for cycles that started in [t0, t1]."""
    start, end, deadline, period = data["start"], data["end"], data["deadline"], float(data["period"])
    inside = (start >= t0) & (start <= t1)
    s, e, d = start[inside], end[inside], deadline[inside]
    periods = np.diff(s)
    hz = 1.0 / periods
    execution = (e - s) * 1e6
    late = (s - d) * 1e6
    # where the lateness comes from: the lock-releasing sleep came back `woke` (kernel wake-up +
    # waiting for the interpreter lock), the lock-holding one `ready` (kernel wake-up only);
    # only cycles whose wait followed the previous cycle (not after an overrun)
    woke, ready = data["woke"][inside][1:], data["ready"][inside][1:]
    waited = woke > e[:-1]
    tail, spin = float(data["wake_tail"]) + float(data["spin_tail"]), float(data["spin_tail"])
    woke_late = (woke[waited] - (d[1:][waited] - tail)) * 1e6
    ready_late = (ready[waited] - (d[1:][waited] - spin)) * 1e6
    # cycles that started over LATE_PERIODS late, and how many of them were the machine's: the
    # witness was late inside them, or the loop's own held sleep (the interpreter lock held, so
    # no Python thread in the way: only the kernel or the hypervisor) came back that late, or
    # its lock-releasing sleep did (below)
    late_starts = np.flatnonzero(late > LATE_PERIODS * period * 1e6)
    shared = None
    witness = "witness_deadline" in data
    if witness or tail > spin or "switches" in data:
        stalls = witness_stalls(data) if witness else None
        held_late = np.zeros(len(s))
        if tail > spin:
            held_late[1:] = np.where(waited, ready - np.maximum(woke, d[1:] - spin), 0.0)
        # the lock-releasing sleep came back late although the loop took the lock straight back
        # (one voluntary context switch: the sleep itself), so not the interpreter lock
        released_late = np.zeros(len(s))
        if "switches" in data:
            alone = waited & (data["switches"][inside][1:] == 1)
            released_late[1:] = np.where(alone, woke - (d[1:] - tail), 0.0)
        shared = sum((witness and witness_was_late(stalls, d[i], s[i])) or held_late[i] > LATE_PERIODS * period
                     or released_late[i] > LATE_PERIODS * period for i in late_starts)
    return dict(late_count=len(late_starts), late_shared=shared,
                woke_p99=np.percentile(woke_late, 99) if len(woke_late) else math.nan,
                ready_p99=np.percentile(ready_late, 99) if len(ready_late) else math.nan,
                cycles=len(s), achieved=len(s) / (t1 - t0), mean_error=abs(hz.mean() - 1.0 / period),
                period_std=hz.std(), exec_mean=execution.mean(), exec_std=execution.std(),
                max_period=periods.max() * 1e3, over_1_5=int((periods > 1.5 * period).sum()),
                over_2=int((periods > 2.0 * period).sum()), p99_period=np.percentile(periods, 99) * 1e3,
                late_p50=np.percentile(late, 50), late_p99=np.percentile(late, 99))


HEADER = (f"{'case':<42} {'rate':>5} {'achvd Hz':>8} {'per std Hz':>10} {'exec us':>8} {'exec std':>8} "
          f"{'max per ms':>10} {'>1.5x':>5} {'>2x':>4} {'p99 ms':>7} {'late p50':>8} {'late p99':>8} "
          f"{'targets':>7} {'rel p99':>7} {'held p99':>8} {'late>T/2 (machine)':>18}")


def row(label: str, rate: int, r: dict) -> str:
    # the targets: ros2_control's WARN lines (5 Hz, 100 us) and no period beyond 2x nominal
    met = r["period_std"] <= 5.0 and r["exec_std"] <= 100.0 and r["over_2"] == 0
    return (f"{label:<42} {rate:>5} {r['achieved']:>8.1f} {r['period_std']:>10.2f} {r['exec_mean']:>8.1f} "
            f"{r['exec_std']:>8.1f} {r['max_period']:>10.2f} {r['over_1_5']:>5} {r['over_2']:>4} "
            f"{r['p99_period']:>7.3f} {r['late_p50']:>8.0f} {r['late_p99']:>8.0f} {'yes' if met else 'no':>7} "
            f"{r['woke_p99']:>7.0f} {r['ready_p99']:>8.0f} {late_starts(r):>18}")


def late_starts(r: dict) -> str:
    """'n' cycles over LATE_PERIODS late, or 'n (m)' with m of them the machine's (by the sleeps or the witness)."""
    return str(r["late_count"]) if r["late_shared"] is None else f"{r['late_count']} ({r['late_shared']})"


def build_wakeup_baseline() -> Path:
    """benchmarks/native/wakeup_baseline.c built with the system's C compiler (cc) into a
    temporary directory; RuntimeError (why not) when it cannot be."""
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        raise RuntimeError("no C compiler (cc) to build benchmarks/native/wakeup_baseline.c")
    binary = Path(tempfile.mkdtemp(prefix="wakeup_baseline_")) / "wakeup_baseline"
    source = ROOT / "benchmarks" / "native" / "wakeup_baseline.c"
    build = subprocess.run([compiler, "-O2", "-o", str(binary), str(source)], capture_output=True, text=True)
    if build.returncode != 0:
        raise RuntimeError(f"cannot build wakeup_baseline.c: {build.stderr.strip()[:200]}")
    return binary


def read_wakeup_log(path: Path) -> tuple:
    """(deadline, start, woke) arrays of wakeup_baseline's OUT_FILE."""
    return tuple(np.fromfile(path, dtype=np.float64).reshape(3, -1))


def loop_defaults() -> tuple:
    """The loop thread's default SCHED_FIFO priority, CPU and spin tail (s), from the node's schema."""
    from controller_manager_py.ros.node import SCHEMA, shared_loop_cpu

    defaults = {p.name: p.default for p in SCHEMA}
    cpu = shared_loop_cpu([c for c in defaults["cpu_affinity"] if c >= 0])
    return defaults["thread_priority"], cpu, defaults["loop.spin_tail"]


def kernel_baseline(rate: int, seconds: float) -> dict:
    """The manager's wait at `rate` in C (benchmarks/native/wakeup_baseline.c) with the loop's
    defaults (priority, CPU, spin tail): the table's figures, or {"error": why not}."""
    try:
        binary = build_wakeup_baseline()
    except RuntimeError as error:
        return {"error": str(error)}
    priority, cpu, spin_s = loop_defaults()
    out = binary.parent / "cycles.bin"
    run = subprocess.run([str(binary), str(priority), str(1e6 / rate), str(seconds), str(cpu),
                          str(spin_s * 1e6), str(out)], capture_output=True, text=True)
    if run.returncode != 0:
        return {"error": f"wakeup_baseline failed ({run.returncode}): {run.stderr.strip()[:200]}"}
    deadline, start, woke = read_wakeup_log(out)
    shutil.rmtree(binary.parent, ignore_errors=True)
    data = {"start": start, "end": start, "deadline": deadline, "woke": woke, "ready": woke,
            "period": 1.0 / rate, "wake_tail": 0.0, "spin_tail": spin_s}
    return timing(data, start[0], start[-1])


class MachineWitness:
    """A witness of the machine beside a case: wakeup_baseline.c on the loop's CPU at a
    SCHED_FIFO priority above the loop's, waking about every millisecond (WITNESS_PERIOD_S)
    with no spin. A late cycle of the manager during which the witness was late too
    (WITNESS_LATE_S) lost its CPU to something above both, the kernel or the hypervisor, not to
    the manager's process. A stall counts only when it covers one of the witness's deadlines by
    more than WITNESS_LATE_S, so short ones are missed: the manager's own count is an upper
    bound. Each wake-up takes the CPU for about 20 us (a virtual machine's): at 1 kHz the loop's
    late-start p99 rises from a few us to about 30 us. It sits on the loop's default CPU: for a
    case that moves or unpins the loop thread, it speaks for that CPU only."""

    def __init__(self):
        self.binary = build_wakeup_baseline()
        self.out = self.binary.parent / "witness.bin"
        self.process = None

    def start(self) -> None:
        priority, cpu, _ = loop_defaults()
        self.process = subprocess.Popen([str(self.binary), str(priority + WITNESS_PRIORITY_ABOVE_LOOP),
                                         str(WITNESS_PERIOD_S * 1e6), "3600", str(cpu), "0", str(self.out)],
                                        stderr=subprocess.PIPE, text=True)

    def stop(self) -> dict:
        """End the witness; its log ({"witness_deadline", "witness_woke"} arrays)."""
        self.process.terminate()        # it writes the cycles so far
        try:
            _, error = self.process.communicate(timeout=10)
            if self.process.returncode != 0:
                raise RuntimeError(f"the machine witness failed ({self.process.returncode}): {error.strip()[:200]}")
            deadline, _, woke = read_wakeup_log(self.out)
            return {"witness_deadline": deadline, "witness_woke": woke}
        finally:
            shutil.rmtree(self.binary.parent, ignore_errors=True)


def witness_stalls(data: dict) -> tuple:
    """(deadlines, wake-ups) of the witness's wakes over WITNESS_LATE_S late: when the machine
    took the CPU."""
    late = data["witness_woke"] - data["witness_deadline"] > WITNESS_LATE_S
    return data["witness_deadline"][late], data["witness_woke"][late]


def witness_was_late(stalls: tuple, deadline: float, start: float) -> bool:
    """Whether one of the witness's `stalls` overlaps a cycle's lateness (its deadline to its start)."""
    stall_deadline, stall_woke = stalls
    return bool(np.any((stall_deadline < start) & (stall_woke > deadline)))


class Busy:
    """`n` processes that each keep a core busy (the stated load), stopped on exit.
    `own_sessions`: each in a session of its own, as a job started from another terminal; with
    the kernel's autogroup scheduling (the default on desktop and server distributions) every
    session then gets an equal share of the CPUs, however many threads it runs."""

    def __init__(self, n: int, own_sessions: bool = False):
        self.processes = [subprocess.Popen([sys.executable, "-c", "while True: pass"], start_new_session=own_sessions)
                          for _ in range(n)]

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        for p in self.processes:
            p.kill()
            p.wait()


def statistics_cost() -> list:
    """In-process: cost of the per-cycle statistics updates and of one registry publish."""
    import rclpy
    from pal_statistics_msgs.msg import Statistics, StatisticsValues

    from controller_manager_py.manager.controller_manager import ControllerManager
    from controller_manager_py.manager.introspection import introspection_entries, statistics_entries
    from controller_manager_py.manager.statistics import PeriodicityStats, Stats
    from controller_manager_py.ros.statistics_publisher import StatisticsRegistry

    rows = []
    p, s, n = PeriodicityStats(), Stats(), 200_000
    t0 = time.perf_counter()
    for k in range(n):
        p.add(k * 0.002, k * 0.002 + 1e-4)
    per_periodic = (time.perf_counter() - t0) / n
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
    rows.append(("statistics updates in the loop, per cycle (always on, 3 ctrl + 1 hw)",
                 (6 * per_periodic + 3 * per_stats) * 1e6))
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
            rows.append((f"~/{label} publish, no subscribers ({len(entries)} entries), per publish",
                         (time.perf_counter() - t0) / reps * 1e6))
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


def interpreter_cost() -> list:
    """In-process, a manager node as ros2_control_node builds it (collection left automatic):
    how long the interpreter lock is held by a garbage collection and by one list_controllers
    call in the executor, the two things that stall a Python loop thread."""
    import gc

    import rclpy
    from controller_manager_msgs.srv import ListControllers
    from rclpy.executors import SingleThreadedExecutor

    from controller_manager_py.ros.node import ControllerManagerNode

    tmp = Path(tempfile.mkdtemp(prefix="cm_cost_"))
    (tmp / "params.yaml").write_text(PARAMS.format(rate=500, first=JOINTS[:3], second=JOINTS[3:]))
    lease = DomainLease()
    context = rclpy.Context()
    ros_args = ["--ros-args", "--params-file", str(tmp / "params.yaml")]
    sys.argv = [sys.argv[0], *ros_args]  # the controllers' nodes take the manager's parameter files from here
    rclpy.init(context=context, domain_id=lease.domain_id, args=[
        *ros_args, "-p", "loop.gc_mode:=automatic",
        "-p", f"robot_description_file:={ROOT / 'config' / 'mock_ur.urdf'}"])
    rows = []
    node = ControllerManagerNode(context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        end = time.monotonic() + 20
        while node.loop is None and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        node.loop.stop()

        def timed(fn, reps):
            samples = []
            for _ in range(reps):
                t0 = time.perf_counter()
                fn()
                samples.append((time.perf_counter() - t0) * 1e3)
            return float(np.median(samples)), max(samples)
        objects = len(gc.get_objects())
        for generation in (0, 1, 2):
            median, worst = timed(lambda g=generation: gc.collect(g), 5)
            rows.append((f"gc.collect({generation}), {objects} tracked objects (ms, median / max)", median, worst))
        gc.freeze()
        median, worst = timed(lambda: gc.collect(2), 5)
        rows.append(("gc.collect(2) after gc.freeze() (ms)", median, worst))
        gc.unfreeze()
        median, worst = timed(lambda: node.cm_services.on_list_controllers(ListControllers.Request(),
                                                                          ListControllers.Response()), 50)
        rows.append(("list_controllers callback in the executor (ms)", median, worst))
        jsb = node.cm.controllers["joint_state_broadcaster"].c
        median, worst = timed(lambda: jsb.update(1.0, 0.002), 200)
        rows.append(("joint_state_broadcaster update: publish /joint_states from the loop (ms)", median, worst))
    finally:
        node.destroy_node()
        context.try_shutdown()
        lease.release()
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--table", choices=("acceptance", "causes", "tails", "cost", "all"), default="acceptance")
    parser.add_argument("--seconds", type=float, default=5.0, help="measuring window per case")
    parser.add_argument("--busy", type=int, default=1, help="busy processes beside the loaded cases")
    parser.add_argument("--rounds", type=int, default=1, help="causes: times each case is run (interleaved)")
    parser.add_argument("--witness", action="store_true", help="a machine witness beside each case: which late "
                        "cycles the kernel or the hypervisor caused (see the module docstring)")
    args = parser.parse_args()

    def case(rate: int, params: dict, subscribe: bool) -> dict:
        return run_case(rate, params, subscribe, args.seconds, witness=args.witness)
    print(f"load average at start: {os.getloadavg()[0]:.2f}; {os.cpu_count()} CPUs; window {args.seconds:g} s")
    if args.table in ("acceptance", "all"):
        print(f"\nacceptance (list_controllers every 100 ms, statistics subscribed)\n{HEADER}")
        with Busy(args.busy):
            print(row(f"defaults, {args.busy} busy process(es)", 500, case(500, {}, True)),
                  flush=True)
        print(row("defaults, no busy process", 1000, case(1000, {}, True)), flush=True)
        baseline = kernel_baseline(1000, args.seconds)
        label = "machine limit: the same wait in C"
        print(f"{label:<42} {baseline['error']}" if "error" in baseline else row(label, 1000, baseline), flush=True)
    if args.table in ("causes", "all"):
        print(f"\ncauses at 500 Hz, {args.busy} busy process(es), list_controllers every 100 ms\n{HEADER}")
        with Busy(args.busy):
            for _ in range(args.rounds):
                for label, params, subscribe in CAUSES:
                    print(row(label, 500, case(500, params, subscribe)), flush=True)
    if args.table in ("tails", "all"):
        print(f"\ntails (list_controllers every 100 ms, statistics subscribed)\n{HEADER}")
        for _ in range(args.rounds):
            for label, params in TAILS:
                with Busy(args.busy):
                    print(row(f"{label}, {args.busy} busy", 500, case(500, params, True)),
                          flush=True)
                print(row(f"{label}, no busy", 1000, case(1000, params, True)), flush=True)
    if args.table in ("cost", "all"):
        print(f"\n{'statistics cost (in-process)':<72} {'us':>8}")
        for label, us in statistics_cost():
            print(f"{label:<72} {us:>8.2f}")
        print(f"\n{'interpreter lock held by (in-process)':<72} {'median':>8} {'max':>8}")
        for label, median, worst in interpreter_cost():
            print(f"{label:<72} {median:>8.3f} {worst:>8.3f}")


if __name__ == "__main__":
    main()
