"""Episode metrics (DESIGN.md section 7; issue 6):

- drop: 1 if the ball left the plate.
- rmse_m: RMS distance between the true ball and the reference over the surviving steps.
- rmse_steady_m: the same after `steady_after_s` (the release transient excluded).
- settle_s: time after release (engagement) until the error stays below 5 mm (inf if never).
- peak_tilt_rad: max |u| over both axes.
- smoothness_rad_s: RMS of the commanded tilt rate du/dt.
- latency_s: mean camera-to-command latency = age of the state at the tick + the domain's
  actuation latency (in lock-step the age is the schedule's, not a machine measurement).
"""
from __future__ import annotations

import math
from typing import Dict

import numpy as np

SETTLE_TOL_M = 0.005
STEADY_AFTER_S = 5.0


def episode_metrics(s: Dict[str, np.ndarray], dropped: bool, duration_s: float,
                    actuation_latency_s: float = 0.0) -> Dict[str, float]:
    t = s["t"]
    err = np.hypot(s["x"] - s["rx"], s["y"] - s["ry"])
    steady = t >= STEADY_AFTER_S
    above = np.nonzero(err >= SETTLE_TOL_M)[0]
    if dropped:
        settle = math.inf
    elif len(above) == 0:
        settle = 0.0
    elif above[-1] == len(t) - 1:
        settle = math.inf
    else:
        settle = float(t[above[-1] + 1])
    dt = np.diff(t)
    du = np.hypot(np.diff(s["ux"]), np.diff(s["uy"])) / np.where(dt > 0, dt, 1.0)
    ages = s["age"][np.isfinite(s["age"])]
    return {
        "drop": float(dropped),
        "survived_s": float(t[-1] + (t[1] - t[0] if len(t) > 1 else 0.0)) if len(t) else 0.0,
        "rmse_m": float(np.sqrt(np.mean(err ** 2))) if len(err) else math.nan,
        "rmse_steady_m": float(np.sqrt(np.mean(err[steady] ** 2))) if np.any(steady) else math.nan,
        "settle_s": settle,
        "peak_tilt_rad": float(np.max(np.abs(np.concatenate([s["ux"], s["uy"]])))) if len(t) else 0.0,
        "smoothness_rad_s": float(np.sqrt(np.mean(du ** 2))) if len(du) else 0.0,
        "latency_s": float(np.mean(ages) + actuation_latency_s) if len(ages) else math.nan,
    }
