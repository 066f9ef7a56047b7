"""Online estimate of the plant: its gain k*g and a constant disturbance acceleration.

The controllers model the ball as x'' = -k g u per plate axis, with k (rolling factor) and g
fixed by parameters. A real plate differs: gravity is what it is, a solid ball rolls at 5/7 g
where a shell rolls at 3/5, friction drags, and a plate mounted slightly off level (or a
tilt offset in the arm's calibration) adds a constant push. The estimator fits

    x'' = -k_g u(t) + d          (per axis; k_g shared by both axes, d = (d_x, d_y))

to the ball positions the tracker reports over a sliding window, with u(t) the plate tilt
actually reached (forward kinematics of /joint_states, so no delay model is needed). Over a
window of samples i with times t_i (tau_i = t_i - t_0), per axis

    p_i = p_0 + v_0 tau_i + d tau_i^2 / 2 - k_g Pi_i,    Pi_i = double integral of u from t_0

is linear in (p_0, v_0, d) per axis and k_g: one small least-squares problem. Positions
rather than velocities: the tracker's velocity is a filtered derivative whose lag correlates
with u, while the double integral Pi grows as tau^2 and dominates the position noise over a
window of a second or two. The fit is regularised toward the current estimate (so a still
plate, which says nothing about k_g, changes nothing) and blended into the estimate with the
time constant `tau_s`; both stay within bounds around the nominal values. A push (or a hand
on the ball) is not the model: each new position is compared with the last fit's prediction,
and two in a row far off (`jump_sigma` times the recent residual, at least `jump_min_m`)
restart the window after the disturbance; a fit whose residual is far above the recent ones
is skipped the same way.

The controllers use the estimate through `k_g` and `accel_offset_m_s2`: the PID scales its
feedback by k_g_nominal / k_g and adds the tilt d / k_g that cancels the disturbance; the MPC
plans in nominal-equivalent tilt v = (k_g u - d) / k_g_nominal with its limits rescaled; the
latency prediction integrates x'' = -k_g u + d.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Deque, Optional, Sequence

import numpy as np

from ball_balance.control.prediction import TiltHistory, predict


@dataclass(frozen=True)
class EstimatorConfig:
    adapt_gain: bool = True             # estimate k_g online (else the nominal value is kept)
    adapt_offset: bool = True           # estimate the constant disturbance d
    window_s: float = 3.0               # regression window (long enough for the tilt to vary in it)
    tau_s: float = 2.0                  # blend time constant of the estimate (docs/control.md)
    gain_min_ratio: float = 0.3         # k_g within [min, max] x nominal
    gain_max_ratio: float = 2.5
    offset_max_m_s2: float = 0.6        # |d| per axis at most (0.6 m/s^2: ~0.1 rad of tilt at 1 g)
    position_noise_m: float = 0.002     # typical error of a tracked position (weights the prior)
    gain_prior_ratio: float = 0.05      # prior 1-sigma of a window's k_g around the estimate (x nominal)
    offset_prior_m_s2: float = 0.01     # prior 1-sigma of a window's d around the estimate
    max_gap_s: float = 0.2              # a gap between states longer than this restarts the window
    outlier_ratio: float = 4.0          # skip a fit with residual above this x the running residual
    jump_sigma: float = 4.0             # a new position this many running residuals off the fit's
    jump_min_m: float = 0.003           # prediction (and at least this far) counts as a disturbance

    @property
    def enabled(self) -> bool:
        return self.adapt_gain or self.adapt_offset


def level_offset_rad(accel_offset_m_s2, k_g: float) -> np.ndarray:
    """The disturbance d as a plate-level offset per axis [rad]: the plate tilt (in the command's
    sign convention, u) at which the ball stays still, asin(d / k_g) with k_g = k g (a plate
    tilted by u accelerates the ball by -k g sin(u); a plate mounted off level by -u, or a force
    F = m g sin(u) on the ball's centre, gives d = k g sin(u))."""
    return np.arcsin(np.clip(np.asarray(accel_offset_m_s2, dtype=float) / k_g, -1.0, 1.0))


def level_offset_deg(accel_offset_m_s2, k_g: float) -> np.ndarray:
    """`level_offset_rad` in degrees, as the statistics report it."""
    return np.degrees(level_offset_rad(accel_offset_m_s2, k_g))


def plant_statistics(plant_of) -> list:
    """(name, getter) entries that report the estimate of the PlantEstimator `plant_of()` returns
    (statistics, introspection): the disturbance as a plate-level offset [deg] per axis and the
    gain ratio (estimated k g / configured)."""
    def offset_deg(axis: int) -> float:
        plant = plant_of()
        return float(level_offset_deg(plant.offset, plant.k_g)[axis])

    return [("disturbance_tilt_x_deg", lambda: offset_deg(0)), ("disturbance_tilt_y_deg", lambda: offset_deg(1)),
            ("plant_gain_ratio", lambda: plant_of().k_g / plant_of().k_g_nominal)]


def level_offset_summary(tilt_x_deg: float, tilt_y_deg: float) -> str:
    """The level offset per axis (plant_statistics' disturbance_tilt_*_deg) in words, for
    /diagnostics: how far the plate is off level as the ball feels it, and which way the ball
    is pushed (plate axes, from +x towards +y; a force set with /sim/set_ball_force towards
    `ball_force_dir_deg` reads as that direction)."""
    size = math.hypot(tilt_x_deg, tilt_y_deg)
    if not math.isfinite(size):
        return f"no estimate (x {tilt_x_deg}, y {tilt_y_deg} deg)"
    towards = math.degrees(math.atan2(tilt_y_deg, tilt_x_deg)) % 360.0
    return (f"plate {size:.2f} deg off level as the ball feels it, pushing it towards {towards:.0f} deg "
            f"(x {tilt_x_deg:+.2f}, y {tilt_y_deg:+.2f} deg)")


class PlantEstimator:
    """Sliding-window least-squares estimate of k_g and d (both axes) from ball positions and
    the plate tilt history. Feed `add_tilt` every tick and `add_state` with each new ball state."""

    def __init__(self, cfg: EstimatorConfig, k_g_nominal: float):
        self.cfg = cfg
        self.k_g_nominal = k_g_nominal
        self.k_g = k_g_nominal
        self.offset = np.zeros(2)               # d [m/s^2]
        self.tilts = TiltHistory(max_len=512)   # plate tilt reached (measured), per tick
        # samples: (t, p_x, p_y, P_x, P_y, V_x, V_y) with P, V the double and single integrals
        # of the tilt from the window's origin
        self._samples: Deque[np.ndarray] = deque()
        self._residual_m: Optional[float] = None   # running RMS residual of accepted fits
        self._last_fit = None        # (first sample of the fit's window, fitted parameters)
        self._jumps = 0              # consecutive new positions far off the last fit's prediction
        self.fits = 0
        self.skipped = 0
        self.restarts = 0            # windows restarted after a disturbance (push)
        self._offset_given = False   # d comes from take_level_offset

    def reset(self) -> None:
        """Forget the window (not the estimate: the plant has not changed)."""
        self._samples.clear()
        self.tilts.clear()

    def take_level_offset(self, level_rad: Sequence[float]) -> None:
        """The disturbance from the tracker's filter, as its plate-level offset per axis [rad]:
        d = k_g sin(level), which the controllers cancel with the tilt `level` whatever k_g is
        (the tracker's filter sees the detections themselves). The window's fit then keeps d
        as given and estimates k_g alone."""
        if self.cfg.adapt_offset and all(math.isfinite(v) for v in level_rad):
            self.offset = np.clip(self.k_g * np.sin(np.asarray(level_rad, dtype=float)),
                                  -self.cfg.offset_max_m_s2, self.cfg.offset_max_m_s2)
            self._offset_given = True

    def add_tilt(self, t_s: float, tilt: Sequence[float]) -> None:
        self.tilts.record(t_s, float(tilt[0]), float(tilt[1]))

    def add_state(self, stamp_s: float, pos_m: Sequence[float]) -> None:
        """A new ball position [m] captured at stamp_s (controller clock)."""
        cfg = self.cfg
        if not cfg.enabled or not all(math.isfinite(v) for v in (stamp_s, pos_m[0], pos_m[1])):
            return
        if self._samples:
            last = self._samples[-1]
            if stamp_s <= last[0]:
                return
            if stamp_s - last[0] > cfg.max_gap_s:
                self._samples.clear()
        if self._samples:
            last = self._samples[-1]
            # integrate the tilt (as acceleration +u) from the last sample: P'' = u
            big_p, big_v = predict(last[3:5], last[5:7], last[0], stamp_s, self.tilts, -1.0)
        else:
            big_p, big_v = np.zeros(2), np.zeros(2)
        sample = np.array([stamp_s, pos_m[0], pos_m[1], *big_p, *big_v])
        if self._off_the_fit(sample):
            self._jumps += 1
            if self._jumps >= 2:   # the ball was pushed: start the window again after it
                self.restarts += 1
                keep = self._samples[-1]
                self._samples.clear()
                self._samples.append(keep)
                self._last_fit = None
                self._jumps = 0
        else:
            self._jumps = 0
        self._samples.append(sample)
        while self._samples and stamp_s - self._samples[0][0] > cfg.window_s:
            self._samples.popleft()
        if len(self._samples) >= 10 and stamp_s - self._samples[0][0] >= 0.5 * cfg.window_s:
            self._fit()

    def _off_the_fit(self, sample: np.ndarray) -> bool:
        """The new position is far from what the last fit predicts for it."""
        if self._last_fit is None or self._residual_m is None:
            return False
        row0, theta = self._last_fit
        tau = sample[0] - row0[0]
        for axis in range(2):
            pi = sample[3 + axis] - row0[3 + axis] - row0[5 + axis] * tau
            predicted = theta[3 * axis] + theta[3 * axis + 1] * tau + 0.5 * theta[3 * axis + 2] * tau ** 2 \
                - theta[6] * pi
            if abs(sample[1 + axis] - predicted) > max(self.cfg.jump_sigma * self._residual_m, self.cfg.jump_min_m):
                return True
        return False

    def _fit(self) -> None:
        cfg = self.cfg
        s = np.array(self._samples)
        t0 = s[0, 0]
        tau = s[:, 0] - t0
        m = len(s)
        # unknowns: [p0x, v0x, dx, p0y, v0y, dy, k_g] (no term in u itself: for a sinusoidal
        # tilt, as on a circle, u and its double integral are collinear and k_g would be lost)
        a = np.zeros((2 * m + 3, 7))
        b = np.zeros(2 * m + 3)
        w = 1.0 / cfg.position_noise_m
        for axis in range(2):
            rows = slice(axis * m, (axis + 1) * m)
            pi = s[:, 3 + axis] - s[0, 3 + axis] - s[0, 5 + axis] * tau   # double integral from t0
            a[rows, 3 * axis] = w
            a[rows, 3 * axis + 1] = w * tau
            a[rows, 3 * axis + 2] = w * 0.5 * tau ** 2
            a[rows, 6] = -w * pi
            b[rows] = w * s[:, 1 + axis]
        # priors: the current estimate, loose enough that an informative window moves it
        k_sigma = cfg.gain_prior_ratio * self.k_g_nominal if cfg.adapt_gain else 1e-9
        d_sigma = cfg.offset_prior_m_s2 if cfg.adapt_offset else 1e-9
        a[2 * m, 6], b[2 * m] = 1.0 / k_sigma, self.k_g / k_sigma
        for axis in range(2):
            a[2 * m + 1 + axis, 3 * axis + 2] = 1.0 / d_sigma
            b[2 * m + 1 + axis] = self.offset[axis] / d_sigma
        theta, *_ = np.linalg.lstsq(a, b, rcond=None)
        residual = float(np.sqrt(np.mean((a[:2 * m] @ theta - b[:2 * m]) ** 2))) * cfg.position_noise_m
        if self._residual_m is not None and residual > cfg.outlier_ratio * max(self._residual_m, 2e-4):
            # not the model (a push, a hand): skip, and restart the window after the disturbance
            self.skipped += 1
            for _ in range(m // 2):
                self._samples.popleft()
            return
        self._residual_m = residual if self._residual_m is None else 0.9 * self._residual_m + 0.1 * residual
        self._last_fit = (s[0].copy(), theta)
        self.fits += 1
        dt = s[-1, 0] - s[-2, 0]
        alpha = min(1.0, dt / cfg.tau_s)
        if cfg.adapt_gain:
            k_new = self.k_g + alpha * (theta[6] - self.k_g)
            self.k_g = float(np.clip(k_new, cfg.gain_min_ratio * self.k_g_nominal,
                                     cfg.gain_max_ratio * self.k_g_nominal))
        if cfg.adapt_offset and not self._offset_given:
            d_new = self.offset + alpha * (theta[[2, 5]] - self.offset)
            self.offset = np.clip(d_new, -cfg.offset_max_m_s2, cfg.offset_max_m_s2)
