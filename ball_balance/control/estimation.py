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

The fit is written once, over arrays: `BatchPlantEstimator` fits a batch of plates at once (the
training plant steps one plate per episode, ball_balance/policy/env.py), and `PlantEstimator`,
which the pipeline runs, is its batch of one with the plate tilt history it integrates.

The controllers use the estimate through `k_g` and `accel_offset_m_s2`: the PID scales its
feedback by k_g_nominal / k_g and adds the tilt d / k_g that cancels the disturbance; the MPC
plans in nominal-equivalent tilt v = (k_g u - d) / k_g_nominal with its limits rescaled; the
latency prediction integrates x'' = -k_g u + d.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

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


# The runtime's ring of samples starts with room for a window at this camera rate (the
# closed-loop benchmark's) and doubles when a faster camera fills it (the simulated one runs at
# 60 Hz, config/sim.yaml): the fit's work grows with the ring's size, not with the samples in it.
RUNTIME_START_RATE_HZ = 30.0


class BatchPlantEstimator:
    """The plant estimate of a batch of plates, each with its own window, fitted all at once:
    per plate the regularised sliding-window least-squares fit of x'' = -k_g u + d (k_g shared
    by both axes) to the tracked positions and the double integral of the plate tilt reached,
    blended in with the time constant tau_s and bounded, and the window restarts (a gap longer
    than max_gap_s, two positions in a row far off the last fit's prediction, a fit far above
    the running residual). Solved through the normal equations. The training plant steps one
    plate per episode (ball_balance/policy/env.py); `PlantEstimator` is the batch of one.

    The plates share one clock. Their samples sit in a ring of `capacity` slots (a call with a
    new position for any plate takes one slot; plates without one get an empty slot there); a
    slot still in a plate's window is never overwritten: the ring grows instead."""

    def __init__(self, batch: int, cfg: EstimatorConfig, k_g_nominal: float, capacity: int):
        self.b, self.cfg, self.k_nom, self.cap = batch, cfg, k_g_nominal, capacity
        self.k_g = np.full(batch, k_g_nominal)
        self.offset = np.zeros((batch, 2))             # d [m/s^2]
        self.offset_given = np.zeros(batch, bool)      # d from take_level_offset: the fit keeps it
        self.t = np.full((batch, capacity), -np.inf)   # sample stamps (ring, -inf: empty)
        self.rows = np.zeros((batch, capacity, 6))     # p_x, p_y, P_x, P_y, V_x, V_y
        self.count = 0                                 # samples written (ring index = count % cap)
        self.t_start = np.full(batch, -np.inf)         # samples before this are out of the window
        self.last_t = np.full(batch, -np.inf)
        self.residual = np.full(batch, np.nan)         # running RMS residual of accepted fits
        self.fit0 = np.zeros((batch, 7))               # (t, row) of the last fit's first sample
        self.theta = np.full((batch, 7), np.nan)       # the last fit's parameters (nan: none)
        self.jumps = np.zeros(batch, int)              # positions in a row far off the last fit
        self.fits = np.zeros(batch, int)
        self.skipped = np.zeros(batch, int)            # fits skipped as far above the running residual
        self.restarts = np.zeros(batch, int)           # windows restarted after a disturbance (push)

    def reset(self) -> None:
        """Forget every plate's window (not the estimate: the plant has not changed)."""
        self.t.fill(-np.inf)
        self.t_start.fill(-np.inf)
        self.last_t.fill(-np.inf)
        self.theta.fill(np.nan)
        self.jumps.fill(0)

    def take_level_offset(self, level_rad) -> None:
        """The disturbance from the tracker's filter, as its plate-level offset (b, 2) [rad]:
        d = k_g sin(level), which the controllers cancel with the tilt `level` whatever k_g is
        (the tracker's filter sees the detections themselves). A plate's window then keeps d
        as given and estimates k_g alone. Plates with a non-finite level are left alone."""
        if not self.cfg.adapt_offset:
            return
        level = np.asarray(level_rad, dtype=float).reshape(self.b, 2)
        ok = np.isfinite(level).all(1)
        self.offset[ok] = np.clip(self.k_g[ok, None] * np.sin(level[ok]),
                                  -self.cfg.offset_max_m_s2, self.cfg.offset_max_m_s2)
        self.offset_given |= ok

    def _in_window(self, now) -> np.ndarray:
        filled = np.isfinite(self.t)
        age = np.where(filled, now[:, None] - np.where(filled, self.t, 0.0), np.inf)
        return filled & (self.t >= self.t_start[:, None]) & (age <= self.cfg.window_s + 1e-9)

    def _grow(self) -> None:
        """Twice the slots, the samples kept in the order they were written."""
        order = (self.count + np.arange(self.cap)) % self.cap
        self.t = np.concatenate([self.t[:, order], np.full((self.b, self.cap), -np.inf)], 1)
        self.rows = np.concatenate([self.rows[:, order], np.zeros((self.b, self.cap, 6))], 1)
        self.count, self.cap = self.cap, 2 * self.cap

    def add_state(self, stamp, pos, big_p, big_v, new) -> None:
        """Per plate with `new` set: a ball position (b, 2) captured at stamp (b,), with the
        double and single integrals (b, 2) of the tilt reached up to then (from any origin that
        stays the same while the window lasts). A stamp not after the plate's last one, or a
        non-finite value, is ignored."""
        cfg = self.cfg
        if not cfg.enabled:
            return
        sample = np.concatenate([pos, big_p, big_v], 1)   # (b, 6): a row of the ring
        new = new & (stamp > self.last_t) & np.isfinite(stamp) & np.isfinite(sample).all(1)
        if not new.any():
            return
        gap = new & (stamp - self.last_t > cfg.max_gap_s)
        self.t_start = np.where(gap, stamp, self.t_start)
        self.theta[gap] = np.nan
        # the new position against the last fit's prediction (a push: restart after it)
        has_residual = np.isfinite(self.residual)
        fitted = new & np.isfinite(self.theta[:, 0]) & has_residual
        tau = (stamp - self.fit0[:, 0])[:, None]
        th = self.theta
        limit = np.maximum(cfg.jump_sigma * np.where(has_residual, self.residual, 0.0), cfg.jump_min_m)
        pi = big_p - self.fit0[:, 3:5] - self.fit0[:, 5:7] * tau   # per axis (b, 2)
        predicted = th[:, [0, 3]] + th[:, [1, 4]] * tau + 0.5 * th[:, [2, 5]] * tau ** 2 - th[:, 6:7] * pi
        off = fitted & (np.abs(pos - predicted) > limit[:, None]).any(1)
        self.jumps = np.where(new, np.where(off, self.jumps + 1, 0), self.jumps)
        restart = new & (self.jumps >= 2)
        self.t_start = np.where(restart, self.last_t, self.t_start)   # keep the last sample
        self.theta[restart] = np.nan
        self.jumps[restart] = 0
        self.restarts += restart
        # write the sample (plates without a new one get an empty slot) into a slot out of every
        # plate's window as of the call's newest stamp (the plates share one clock)
        slot_t = self.t[:, self.count % self.cap]
        if np.any(slot_t >= np.maximum(self.t_start, stamp[new].max() - cfg.window_s - 1e-6)):
            self._grow()
        i = self.count % self.cap
        self.count += 1
        self.t[:, i] = np.where(new, stamp, -np.inf)
        self.rows[:, i] = np.where(new[:, None], sample, 0.0)
        self.last_t = np.where(new, stamp, self.last_t)
        now = np.where(new, stamp, -np.inf)
        mask = self._in_window(now) & new[:, None]
        m = mask.sum(1)
        t_masked = np.where(mask, self.t, np.inf)
        first = np.argmin(t_masked, 1)
        t0 = self.t[np.arange(self.b), first]
        due = new & (m >= 10) & (stamp - t0 >= 0.5 * cfg.window_s)
        if due.any():
            self._fit(np.flatnonzero(due), mask, first, t0, m)

    def _fit(self, idx, mask, first, t0, m) -> None:
        cfg = self.cfg
        w = 1.0 / cfg.position_noise_m
        mk = mask[idx].astype(float)                   # (n, C): 1 in the window, 0 else
        rows, row0 = self.rows[idx], self.rows[idx, first[idx]]
        tau = np.where(mask[idx], self.t[idx] - t0[idx, None], 0.0)
        n, c = mk.shape
        # unknowns: [p0x, v0x, dx, p0y, v0y, dy, k_g] (no term in u itself: for a sinusoidal
        # tilt, as on a circle, u and its double integral are collinear and k_g would be lost)
        a = np.zeros((n, 2, c, 7))
        bvec = np.zeros((n, 2, c))
        for axis in range(2):
            pi = rows[:, :, 2 + axis] - row0[:, None, 2 + axis] - row0[:, None, 4 + axis] * tau   # from t0
            a[:, axis, :, 3 * axis] = w
            a[:, axis, :, 3 * axis + 1] = w * tau
            a[:, axis, :, 3 * axis + 2] = w * 0.5 * tau ** 2
            a[:, axis, :, 6] = -w * pi
            bvec[:, axis] = w * rows[:, :, axis]
        a *= mk[:, None, :, None]
        bvec *= mk[:, None, :]
        a, bvec = a.reshape(n, 2 * c, 7), bvec.reshape(n, 2 * c)
        # priors: the current estimate, loose enough that an informative window moves it
        k_sigma = cfg.gain_prior_ratio * self.k_nom if cfg.adapt_gain else 1e-9
        d_sigma = cfg.offset_prior_m_s2 if cfg.adapt_offset else 1e-9
        ata = np.einsum("nri,nrj->nij", a, a)
        atb = np.einsum("nri,nr->ni", a, bvec)
        ata[:, 6, 6] += 1.0 / k_sigma ** 2
        atb[:, 6] += self.k_g[idx] / k_sigma ** 2
        for axis in range(2):
            ata[:, 3 * axis + 2, 3 * axis + 2] += 1.0 / d_sigma ** 2
            atb[:, 3 * axis + 2] += self.offset[idx, axis] / d_sigma ** 2
        theta = np.linalg.solve(ata, atb[..., None])[..., 0]
        err = np.einsum("nri,ni->nr", a, theta) - bvec
        residual = np.sqrt(np.sum(err ** 2, 1) / (2 * m[idx])) * cfg.position_noise_m
        run = self.residual[idx]
        has_run = np.isfinite(run)
        outlier = has_run & (residual > cfg.outlier_ratio * np.maximum(np.where(has_run, run, 0.0), 2e-4))
        # an outlier fit (a push, a hand): skipped, the window restarts after its older half
        sk = idx[outlier]
        if len(sk):
            t_sorted = np.sort(np.where(mask[sk], self.t[sk], np.inf), 1)
            self.t_start[sk] = t_sorted[np.arange(len(sk)), m[sk] // 2]
            self.skipped[sk] += 1
        ok, theta, residual = idx[~outlier], theta[~outlier], residual[~outlier]
        run = self.residual[ok]
        self.residual[ok] = np.where(np.isfinite(run), 0.9 * run + 0.1 * residual, residual)
        self.fit0[ok] = np.concatenate([t0[ok, None], self.rows[ok, first[ok]]], 1)
        self.theta[ok] = theta
        self.fits[ok] += 1
        # the time between the window's last two samples
        t_sorted = np.sort(np.where(mask[ok], self.t[ok], -np.inf), 1)
        dt = t_sorted[:, -1] - t_sorted[:, -2]
        alpha = np.minimum(1.0, dt / cfg.tau_s)
        if cfg.adapt_gain:
            k_new = self.k_g[ok] + alpha * (theta[:, 6] - self.k_g[ok])
            self.k_g[ok] = np.clip(k_new, cfg.gain_min_ratio * self.k_nom, cfg.gain_max_ratio * self.k_nom)
        if cfg.adapt_offset:
            d_new = self.offset[ok] + alpha[:, None] * (theta[:, [2, 5]] - self.offset[ok])
            blend = ~self.offset_given[ok, None]
            self.offset[ok] = np.where(blend, np.clip(d_new, -cfg.offset_max_m_s2, cfg.offset_max_m_s2),
                                       self.offset[ok])


class PlantEstimator:
    """The plant estimate of one plate (both axes): `BatchPlantEstimator`'s batch of one, with
    the plate tilt history it integrates. Feed `add_tilt` every tick and `add_state` with each
    new ball state; read `k_g` and `offset`."""

    def __init__(self, cfg: EstimatorConfig, k_g_nominal: float):
        self.cfg = cfg
        self.k_g_nominal = k_g_nominal
        self.tilts = TiltHistory(max_len=512)   # plate tilt reached (measured), per tick
        self.batch = BatchPlantEstimator(1, cfg, k_g_nominal,
                                         int(math.ceil(cfg.window_s * RUNTIME_START_RATE_HZ)) + 8)
        # the double and single integrals of the tilt at the last sample, from the window's origin
        self._big_p, self._big_v = np.zeros(2), np.zeros(2)

    @property
    def k_g(self) -> float:
        return float(self.batch.k_g[0])

    @k_g.setter
    def k_g(self, value: float) -> None:
        self.batch.k_g[0] = value

    @property
    def offset(self) -> np.ndarray:
        """d [m/s^2] per axis (a copy: the estimate as of now)."""
        return self.batch.offset[0].copy()

    @offset.setter
    def offset(self, value) -> None:
        self.batch.offset[0] = value

    @property
    def fits(self) -> int:
        return int(self.batch.fits[0])

    @property
    def skipped(self) -> int:
        return int(self.batch.skipped[0])

    @property
    def restarts(self) -> int:
        """Windows restarted after a disturbance (push)."""
        return int(self.batch.restarts[0])

    def reset(self) -> None:
        """Forget the window (not the estimate: the plant has not changed)."""
        self.batch.reset()
        self.tilts.clear()

    def take_level_offset(self, level_rad: Sequence[float]) -> None:
        """The disturbance from the tracker's filter, as its plate-level offset per axis [rad]
        (`BatchPlantEstimator.take_level_offset`): the window's fit then keeps d as given and
        estimates k_g alone."""
        self.batch.take_level_offset(np.array([[float(level_rad[0]), float(level_rad[1])]]))

    def add_tilt(self, t_s: float, tilt: Sequence[float]) -> None:
        self.tilts.record(t_s, float(tilt[0]), float(tilt[1]))

    def add_state(self, stamp_s: float, pos_m: Sequence[float]) -> None:
        """A new ball position [m] captured at stamp_s (controller clock)."""
        cfg = self.cfg
        stamp, pos = float(stamp_s), np.array([pos_m[0], pos_m[1]], dtype=float)
        last = self.batch.last_t[0]
        if not cfg.enabled or not (math.isfinite(stamp) and np.isfinite(pos).all()) or not stamp > last:
            return
        if stamp - last > cfg.max_gap_s:   # a new window (the batch's gap): integrate from here
            self._big_p, self._big_v = np.zeros(2), np.zeros(2)
        else:   # integrate the tilt (as acceleration +u) from the last sample: P'' = u
            self._big_p, self._big_v = predict(self._big_p, self._big_v, last, stamp, self.tilts, -1.0)
        self.batch.add_state(np.array([stamp]), pos[None], self._big_p[None], self._big_v[None], np.ones(1, bool))
