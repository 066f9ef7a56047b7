#!/usr/bin/env python3
"""The fastest any controller can bring a pushed ball back: a lower bound on push recovery.

A push gives the ball a velocity v0 along one plate axis (or along the diagonal, where both
axes brake at once). No controller can act before a dead time (the frame that shows the push,
the tracker, the control tick, the command's way to the plate); after it the plate tilts
within the tilt limit, at most at the tilt-rate limit, and the ball obeys x'' = -k g u
(sin u ~ u: 0.4 % at 0.15 rad). The benchmark's recovery is the time from the push until the
error is within the band (5 mm) and stays there for the hold (0.5 s). The bound is the least
such time for which some tilt history exists: a linear feasibility problem in the tilts on a
5 ms grid (scipy's HiGHS), bisected over the time. It knows the push in advance (no
detection, no noise), so a real controller is slower.

    python benchmarks/push_floor.py
    python benchmarks/push_floor.py --speeds 0.15,0.3 --dead-times 0.05,0.1 --rates 1.5,inf
"""
from __future__ import annotations

import argparse
import math
import os
import sys

import numpy as np
from scipy.optimize import linprog

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from ball_balance.benchmark.metrics import RECOVER_HOLD_S  # noqa: E402
from ball_balance.control.config import COMMON_SCHEMA  # noqa: E402

BAND_M = 0.005   # the recovery figures' band
STEP_S = 0.005


def feasible(v0: float, dead_s: float, rate_rad_s: float, u_max: float, k_g: float, band_m: float,
             recover_s: float) -> bool:
    """Whether some tilt history brings a ball pushed to v0 (one axis) within band_m by
    recover_s and keeps it there for the hold."""
    n = int(round((recover_s + RECOVER_HOLD_S) / STEP_S))
    first = int(math.ceil(dead_s / STEP_S))   # the first step whose tilt a controller sets
    free = n - first
    if free <= 0:
        return False
    # x_k = v0 k h - k_g h^2 sum_{j<k} (k - j - 1/2) u_j over the free tilts u_j (j >= first)
    k = np.arange(1, n + 1)[:, None]
    j = np.arange(first, n)[None, :]
    lever = np.where(j < k, (k - j - 0.5) * k_g * STEP_S ** 2, 0.0)
    drift = v0 * STEP_S * k[:, 0]
    inside = np.arange(1, n + 1) * STEP_S >= recover_s - 1e-9
    A = np.vstack([-lever[inside], lever[inside]])            # |drift - lever u| <= band
    b = np.concatenate([band_m - drift[inside], band_m + drift[inside]])
    if math.isfinite(rate_rad_s):   # |u_j - u_{j-1}| <= rate h, the tilt 0 before the first
        d = np.eye(free) - np.eye(free, k=-1)
        A = np.vstack([A, d, -d])
        b = np.concatenate([b, np.full(2 * free, rate_rad_s * STEP_S)])
    result = linprog(np.zeros(free), A_ub=A, b_ub=b, bounds=[(-u_max, u_max)] * free, method="highs")
    return result.status == 0


def floor_s(v0: float, dead_s: float, rate_rad_s: float, u_max: float, k_g: float, band_m: float) -> float:
    """The least recovery time (to the grid's step) by bisection."""
    lo, hi = 0.0, 0.5
    while not feasible(v0, dead_s, rate_rad_s, u_max, k_g, band_m, hi):
        lo, hi = hi, 2.0 * hi
        if hi > 20.0:
            return math.inf
    while hi - lo > STEP_S:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if feasible(v0, dead_s, rate_rad_s, u_max, k_g, band_m, mid) else (mid, hi)
    return hi


def main(argv=None) -> int:
    defaults = {p.name: p.default for p in COMMON_SCHEMA}
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--speeds", default="0.15,0.3", help="push speeds [m/s], comma-separated")
    ap.add_argument("--dead-times", default="0.05,0.075,0.1", help="dead times [s], comma-separated")
    ap.add_argument("--rates", default="1.5,3,inf", help="tilt-rate limits [rad/s], comma-separated")
    args = ap.parse_args(argv)
    u_max = defaults["max_tilt_cmd_rad"]
    k_g = defaults["rolling_factor"] * defaults["gravity_m_s2"]
    print(f"tilt limit {u_max} rad per axis, k g {k_g:.3f} m/s^2 per rad, band {BAND_M * 1e3:.0f} mm, "
          f"hold {RECOVER_HOLD_S} s")
    print(f"{'push m/s':>8} {'dead s':>7} {'rate rad/s':>10} | {'along an axis s':>15} {'diagonal s':>10}")
    for v0 in (float(s) for s in args.speeds.split(",")):
        for dead in (float(s) for s in args.dead_times.split(",")):
            for rate in (float(s) for s in args.rates.split(",")):
                axis = floor_s(v0, dead, rate, u_max, k_g, BAND_M)
                # diagonal: each axis brakes v0 / sqrt(2) within its own limit, in a box
                # inside the band
                diagonal = floor_s(v0 / math.sqrt(2.0), dead, rate, u_max, k_g, BAND_M / math.sqrt(2.0))
                print(f"{v0:8.2f} {dead:7.3f} {rate:10.1f} | {axis:15.3f} {diagonal:10.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
