"""Joint trajectory controller cost on this machine, in-process (mock UR arm, no ROS graph).

Cases, one table row each (the controller's update() as the loop calls it, per cycle, us):
  hold              active, nothing to follow
  topic trajectory  following a 10-point trajectory, default tolerances, joint limits on
  goal, tolerances  the same as an action goal with path and goal tolerances on every joint
  no limits         the topic trajectory without a robot description (no limiter pass)
and the edge cost of checking a trajectory (accept(): names, values, limits) per point count.
Cases are interleaved over --rounds so a change in the machine's load hits all alike.

    source env.sh && python benchmarks/trajectory_bench.py [--cycles 2000] [--rounds 3]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "controller_manager_py"))
sys.path.insert(0, str(ROOT / "controller_manager_py" / "test"))

from builtin_interfaces.msg import Duration  # noqa: E402
from cm_helpers import HOME, JOINTS, MOCK_UR, make_manager  # noqa: E402
from control_msgs.msg import JointTolerance  # noqa: E402
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint  # noqa: E402

from controller_manager_py.controllers import tolerances as tol  # noqa: E402
from controller_manager_py.controllers.joint_trajectory import GoalRun  # noqa: E402

JTC = "joint_trajectory_controller/JointTrajectoryController"
RATE = 500


def trajectory(points: int, span_s: float = 4.0) -> JointTrajectory:
    msg = JointTrajectory(joint_names=list(JOINTS))
    for k in range(1, points + 1):
        t = span_s * k / points
        offset = 0.2 * np.sin(np.pi * k / points)
        msg.points.append(JointTrajectoryPoint(positions=[h + offset for h in HOME],
                                               time_from_start=Duration(sec=int(t), nanosec=int((t % 1) * 1e9))))
    return msg


def controller(with_limits: bool):
    cm = make_manager(rate=RATE)
    cm.load_controller("jtc", JTC, {"joints": JOINTS})
    jtc = cm.controllers["jtc"].c
    jtc.robot_description = MOCK_UR if with_limits else ""
    cm.configure_controller("jtc")
    cm.switch_controller(["jtc"], [], 2)
    return cm, jtc


def update_cost_us(case: str, cycles: int) -> np.ndarray:
    cm, jtc = controller(with_limits=case != "no limits")
    if case in ("topic trajectory", "no limits"):
        jtc.offer(jtc.accept(trajectory(10)))
    elif case == "goal, tolerances":
        run, _ = tol.goal_tolerances(jtc.default_tolerances, jtc.joints,
                                     [JointTolerance(name=j, position=0.5) for j in JOINTS],
                                     [JointTolerance(name=j, position=0.01) for j in JOINTS], 1.0)
        jtc.offer(jtc.accept(trajectory(10), GoalRun(run)))
    costs, update = [], jtc.update

    def timed(time_s, period_s):  # the manager's cycle calls this in place of update()
        start = time.perf_counter()
        result = update(time_s, period_s)
        costs.append((time.perf_counter() - start) * 1e6)
        return result

    jtc.update = timed
    period, t = 1.0 / RATE, 0.0
    for _ in range(cycles):
        t += period
        cm.cycle(t, period)
    return np.array(costs)


def accept_cost_us(points: int, repeats: int = 50) -> float:
    _, jtc = controller(with_limits=True)
    msg = trajectory(points)
    start = time.perf_counter()
    for _ in range(repeats):
        jtc.accept(msg)
    return (time.perf_counter() - start) / repeats * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cycles", type=int, default=2000, help="update() calls per case and round (500 Hz)")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    cases = ["hold", "topic trajectory", "goal, tolerances", "no limits"]
    samples = {c: [] for c in cases}
    for _ in range(args.rounds):
        for case in cases:
            samples[case].append(update_cost_us(case, args.cycles))
    print(f"update() per cycle, us ({args.rounds} x {args.cycles} cycles at {RATE} Hz)")
    print("| case | mean | p50 | p99 | max |\n|---|---|---|---|---|")
    for case in cases:
        x = np.concatenate(samples[case])
        print(f"| {case} | {x.mean():.1f} | {np.percentile(x, 50):.1f} | {np.percentile(x, 99):.1f} | {x.max():.0f} |")
    print("\naccept() (edge, executor thread), us per trajectory")
    print("| points | us |\n|---|---|")
    for points in (1, 10, 100, 1000):
        print(f"| {points} | {accept_cost_us(points):.0f} |")


if __name__ == "__main__":
    main()
