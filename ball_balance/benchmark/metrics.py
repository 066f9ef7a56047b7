"""Episode metrics (docs/design.md section 7):

- drop: 1 if the ball left the plate.
- rmse_m: RMS distance between the true ball and the reference over the surviving steps.
- rmse_steady_m: the same after `steady_after_s` (the release transient excluded).
- settle_s: time after release (engagement) until the error stays below 5 mm (inf if never).
- peak_tilt_rad: max |u| over both axes.
- smoothness_rad_s: RMS of the commanded tilt rate du/dt.
- latency_s: mean camera-to-command latency = age of the state at the tick + the domain's
  actuation latency (in lock-step the age is the schedule's, not a machine measurement).
- engaged_frac: share of the steps with the controller engaged (the rest counts as error
  against the reference all the same).
- push_recover_s / push_recover_max_s: per push (or force), time until the error is back
  within 5 mm and stays there for RECOVER_HOLD_S (or until the next push); mean and worst.
  inf when it never does; absent without pushes.
- pushes / pushes_late: how many pushes (or forces) there were, and how many of them took longer
  than PUSH_GOAL_S to recover (the push goal: back within 5 mm in at most 1 s).
- step_recover_s / step_recover_max_s / steps / steps_unrecovered: the same for each step of
  a held force (Force with step=True: its start, a change, its end), mean and worst, and how
  many steps were not back within 5 mm (for RECOVER_HOLD_S) before the next; absent without
  steps.
- step_steady_m: per step, the mean error over the last STEP_STEADY_WINDOW_S before the next
  step (or the end), i.e. the error left once settled under (or after) the load; the worst
  step's. Absent without steps, nan after a drop.
- rmse_release_m (`release_rmse`): the reference system's figure, RMS error sampled at 30 Hz
  from the release (not the engagement) over the steps before a drop.
"""
from __future__ import annotations

import math
from typing import Dict, List, Sequence

import numpy as np

SETTLE_TOL_M = 0.005
STEADY_AFTER_S = 5.0
RECOVER_HOLD_S = 0.5
PUSH_GOAL_S = 1.0
STEP_STEADY_WINDOW_S = 1.0


def release_rmse(s: Dict[str, np.ndarray], rate_hz: float = 30.0) -> float:
    """RMS error of the steps sampled at `rate_hz` from the series' start (the release)."""
    t = s["t"]
    if not len(t):
        return math.nan
    step = np.floor((t - t[0]) * rate_hz + 1e-9)
    first_of_step = np.concatenate([[True], np.diff(step) > 0])
    err = np.hypot(s["x"] - s["rx"], s["y"] - s["ry"])[first_of_step]
    return float(np.sqrt(np.mean(err ** 2)))


def recovery_times(t: np.ndarray, err: np.ndarray, push_times_s: Sequence[float], dropped: bool) -> List[float]:
    """Per push: seconds until err < SETTLE_TOL_M holds for RECOVER_HOLD_S (or to the next push)."""
    out = []
    pushes = sorted(push_times_s)
    for i, tp in enumerate(pushes):
        end = pushes[i + 1] if i + 1 < len(pushes) else math.inf
        window = (t >= tp) & (t < end)
        tw, ew = t[window], err[window]
        recovered = math.inf
        inside = ew < SETTLE_TOL_M
        for k in np.nonzero(inside & np.concatenate([[True], ~inside[:-1]]))[0]:  # each entry into the band
            stays = np.nonzero(~inside[k:])[0]
            if not len(stays) and not dropped:   # inside until the next push or the end
                recovered = float(tw[k] - tp)
                break
            if len(stays) and tw[k + stays[0]] - tw[k] >= RECOVER_HOLD_S:
                recovered = float(tw[k] - tp)
                break
        out.append(recovered)
    return out


def recovery_summary(recoveries: Sequence[float]) -> tuple:
    """(mean, worst) of per-event recovery times; the mean is inf when any event never recovered."""
    finite = [r for r in recoveries if math.isfinite(r)]
    mean_s = float(np.mean(finite)) if len(finite) == len(recoveries) else math.inf
    return mean_s, float(max(recoveries))


def step_steady_errors(t: np.ndarray, err: np.ndarray, step_times_s: Sequence[float]) -> List[float]:
    """Per step: the mean error over the last STEP_STEADY_WINDOW_S before the next step (or
    the series' end); nan where that window holds no sample."""
    steps = sorted(step_times_s)
    ends = steps[1:] + [t[-1] + 1e-9]
    out = []
    for start, end in zip(steps, ends, strict=True):
        window = (t >= max(start, end - STEP_STEADY_WINDOW_S)) & (t < end)
        out.append(float(np.mean(err[window])) if np.any(window) else math.nan)
    return out


def episode_metrics(s: Dict[str, np.ndarray], dropped: bool, duration_s: float,
                    actuation_latency_s: float = 0.0, push_times_s: Sequence[float] = (),
                    step_times_s: Sequence[float] = ()) -> Dict[str, float]:
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
    metrics = {
        "drop": float(dropped),
        "survived_s": float(t[-1] + (t[1] - t[0] if len(t) > 1 else 0.0)) if len(t) else 0.0,
        "rmse_m": float(np.sqrt(np.mean(err ** 2))) if len(err) else math.nan,
        "rmse_steady_m": float(np.sqrt(np.mean(err[steady] ** 2))) if np.any(steady) else math.nan,
        "settle_s": settle,
        "peak_tilt_rad": float(np.max(np.abs(np.concatenate([s["ux"], s["uy"]])))) if len(t) else 0.0,
        "smoothness_rad_s": float(np.sqrt(np.mean(du ** 2))) if len(du) else 0.0,
        "latency_s": float(np.mean(ages) + actuation_latency_s) if len(ages) else math.nan,
        "engaged_frac": float(np.mean(s["mode"] > 0)) if len(t) and "mode" in s else math.nan,
    }
    recoveries = recovery_times(t, err, push_times_s, dropped) if len(t) else []
    if recoveries:
        metrics["push_recover_s"], metrics["push_recover_max_s"] = recovery_summary(recoveries)
        metrics["pushes"] = float(len(recoveries))
        metrics["pushes_late"] = float(sum(r > PUSH_GOAL_S for r in recoveries))
    steps = recovery_times(t, err, step_times_s, dropped) if len(t) else []
    if steps:
        metrics["step_recover_s"], metrics["step_recover_max_s"] = recovery_summary(steps)
        metrics["steps"] = float(len(steps))
        metrics["steps_unrecovered"] = float(sum(not math.isfinite(r) for r in steps))
        metrics["step_steady_m"] = math.nan if dropped else float(np.max(step_steady_errors(t, err, step_times_s)))
    return metrics
