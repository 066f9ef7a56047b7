#!/usr/bin/env python3
"""MPC solve time per tick (both axes, one OSQP solve, vector updates included), in closed
loop on the ideal double integrator, for three situations; prints p50 / p99 / max in us.

    python benchmarks/mpc_solve_bench.py [--ticks 3000]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ball_balance.control.mpc import MpcConfig, PlateMpc, preview  # noqa: E402
from ball_balance.control.references import Circle, FigureEight, Stationary  # noqa: E402

SCENARIOS = {
    "circle r=0.10 T=10 (constraints inactive)": (Circle(0.10, 10.0), (0.10, 0.0), (0.0, 0.0), 0.0),
    "release at 0.15 m, 0.3 m/s (tilt and rate limits active)": (Stationary(), (0.15, -0.12), (0.3, 0.0), 0.0),
    "figure-eight, 2 mm measurement noise": (FigureEight(0.10, 12.0), (0.0, 0.0), (0.0, 0.0), 0.002),
}


def run(reference, x0, v0, noise_m, ticks, rng):
    mpc = PlateMpc(MpcConfig())
    dt, kg = mpc.cfg.dt_s, mpc.cfg.k_g
    x, v, u = np.array(x0, float), np.array(v0, float), np.zeros(2)
    times = []
    for i in range(ticks):
        p, pv, pa = preview(reference, i * dt, dt, mpc.cfg.horizon)
        u = np.array(mpc.solve(x + rng.normal(0, noise_m, 2), v, p, pv, pa, u))
        times.append(mpc.last_solve_s)
        a = -kg * u
        x, v = x + v * dt + 0.5 * a * dt * dt, v + a * dt
    return np.array(times) * 1e6, mpc.failures


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--ticks", type=int, default=3000)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    print(f"{'scenario':60} {'p50 us':>8} {'p99 us':>8} {'max us':>8} {'fallbacks':>9}")
    for name, (reference, x0, v0, noise) in SCENARIOS.items():
        t, failures = run(reference, x0, v0, noise, args.ticks, rng)
        print(f"{name:60} {np.percentile(t, 50):8.1f} {np.percentile(t, 99):8.1f} {t.max():8.0f} {failures:9d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
