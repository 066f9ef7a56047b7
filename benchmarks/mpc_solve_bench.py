#!/usr/bin/env python3
"""MPC solve time per tick (both axes, one OSQP solve, vector updates included), in closed
loop on the ideal double integrator, for three situations; prints p50 / p99 / max in us and
the ticks that needed OSQP (the others' unconstrained optimum met every constraint).
`--busy N` starts N processes that each keep a core busy while it runs (the load the
figures are stated under: one other busy process); the load average at start is printed. By
default the ticks run back to back (a process that never sleeps: the scheduler preempts it
like any CPU hog, which shows in p99 when the machine is shared); `--pace-ms P` sleeps until
the next multiple of P ms between ticks, as the controller node does between ball states.
`--priority P` runs the ticks at SCHED_FIFO P, as the controller nodes' `thread_priority`
does (needs CAP_SYS_NICE; says so when refused).

    python benchmarks/mpc_solve_bench.py [--ticks 3000] [--busy 1] [--pace-ms 5] [--priority 45]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "controller_manager_py"))  # its own package folder

from ball_balance.control.mpc import MpcConfig, PlateMpc, preview  # noqa: E402
from ball_balance.control.references import Circle, FigureEight, Stationary  # noqa: E402

SCENARIOS = {
    "circle r=0.10 T=10 (constraints inactive)": (Circle(0.10, 10.0), (0.10, 0.0), (0.0, 0.0), 0.0),
    "release at 0.15 m, 0.3 m/s (tilt and rate limits active)": (Stationary(), (0.15, -0.12), (0.3, 0.0), 0.0),
    "figure-eight, 2 mm measurement noise": (FigureEight(0.10, 12.0), (0.0, 0.0), (0.0, 0.0), 0.002),
}


def run(reference, x0, v0, noise_m, ticks, rng, pace_s=0.0):
    mpc = PlateMpc(MpcConfig())
    dt, kg = mpc.cfg.dt_s, mpc.cfg.k_g
    x, v, u = np.array(x0, float), np.array(v0, float), np.zeros(2)
    times = []
    next_tick = time.monotonic()
    for i in range(ticks):
        if pace_s > 0.0:
            next_tick += pace_s
            time.sleep(max(0.0, next_tick - time.monotonic()))
        p, pv, pa = preview(reference, i * dt, dt, mpc.cfg.horizon)
        u = np.array(mpc.solve(x + rng.normal(0, noise_m, 2), v, p, pv, pa, u))
        times.append(mpc.last_solve_s)
        a = -kg * u
        x, v = x + v * dt + 0.5 * a * dt * dt, v + a * dt
    return np.array(times) * 1e6, mpc.failures, ticks - getattr(mpc, "unconstrained", 0)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--ticks", type=int, default=3000)
    parser.add_argument("--busy", type=int, default=0, help="processes that each keep a core busy meanwhile")
    parser.add_argument("--priority", type=int, default=0, help="SCHED_FIFO priority of the ticks (0: normal)")
    parser.add_argument("--pace-ms", type=float, default=0.0, help="one tick per this many ms (0: back to back)")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    print(f"load average at start: {os.getloadavg()[0]:.2f}; {os.cpu_count()} CPUs; {args.busy} busy process(es); "
          + (f"one tick every {args.pace_ms:g} ms" if args.pace_ms > 0 else "ticks back to back"))
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy)]
    try:
        if args.priority > 0:  # (after starting the busy processes: they would inherit it)
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.priority))
                print(f"ticks at SCHED_FIFO {args.priority}")
            except (OSError, ValueError) as error:
                print(f"SCHED_FIFO {args.priority} refused ({error}): ticks at normal priority")
        print(f"{'scenario':60} {'p50 us':>8} {'p99 us':>8} {'max us':>8} {'fallbacks':>9} {'OSQP ticks':>10}")
        for name, (reference, x0, v0, noise) in SCENARIOS.items():
            t, failures, solver_ticks = run(reference, x0, v0, noise, args.ticks, rng, args.pace_ms / 1e3)
            print(f"{name:60} {np.percentile(t, 50):8.1f} {np.percentile(t, 99):8.1f} {t.max():8.0f} "
                  f"{failures:9d} {solver_ticks:10d}")
    finally:
        for process in busy:
            process.kill()
            process.wait()
    return 0


if __name__ == "__main__":
    sys.exit(main())
