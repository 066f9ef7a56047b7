"""The tracker's Kalman filter (ball_balance/vision/kalman.py BallKalman) over a batch of balls,
for the vectorised training plant: the same model and the same adaptations, numpy, all balls
at once. Built from the same settings (KalmanConfig.from_tracker of the tracker's config), so
the plant follows whatever config/ball_tracker.yaml and the tracker's schema set.

Per ball: state [x, y, vx, vy, s] (s the input gain; held at 1 with zero variance when
`estimate_input_gain` is off, which is then the plain known-acceleration model), the commanded
tilt's known acceleration, process noise raised by the running innovation consistency, the
measurement noise estimated from the detections' scatter (the tracker's own
DetectionNoiseEstimator, over the batch), the gate, coasting and track restarts (the gain estimate
survives them). filterpy's update (Joseph form) is reproduced step for step; a test checks the
batch against BallKalman on the same detections.

With `disturbance_time_constant_s` > 0 the state also holds d = (d_x, d_y), the acceleration
the known one does not explain, with BallKalman's change test and its estimate of a change
(vision/disturbance.py ChangeTest: the same code, over the batch). BallKalman's jump test
after a push's detection (was it a push or a force that started or turned?) is left out: the
training plant's plate bias is constant from the start of an episode, and a push there is
always a push.
"""
from __future__ import annotations

import numpy as np

from ball_balance.vision.disturbance import (
    MODEL_AGREED_NIS,
    ChangeTest,
    consistency_settle_s,
)
from ball_balance.vision.kalman import (
    DetectionNoiseEstimator,
    KalmanConfig,
    add_white_acceleration,
    prediction,
    process_noise,
)

D_INDEX = 5       # the state's index of d_x (d_y next) with the disturbance state (s is 4)


class BatchBallKalman:
    """`step(t, z, arrived, accel)` once per frame (one stamp for the whole batch)."""

    def __init__(self, batch: int, cfg: KalmanConfig, fixed_meas_noise_m=None, window_max_span_s: float = 0.25,
                 noise_min_samples: int = 10):
        self.b, self.cfg = batch, cfg
        # a detection beyond maneuver_sigma widens its frame's prediction
        self.maneuver_sigma = cfg.maneuver_sigma
        # ... and, while the model had agreed, the velocity of a constant-velocity filter run
        # alongside for maneuver_hold_s (BallKalman.fast)
        self.hold_until = np.full(batch, -np.inf)
        # with maneuver_confirm_frames > 1 (BallKalman._excess): detections in the current run that may
        # be a push, the last one's innovation, the consistency before the run began
        self.excess_count = np.zeros(batch, int)
        self.excess_y = np.zeros((batch, 2))
        self.excess_nis = np.ones(batch)
        self.fast = None
        if cfg.maneuver_hold_s > 0.0 and cfg.maneuver_sigma > 0.0:
            self.fast = BatchBallKalman(batch, cfg.constant_velocity())
        self.last_dt = np.zeros(batch)                 # (dt, q) of each ball's last prediction
        self.last_q = np.zeros(batch)
        self.sigma_a = cfg.accel_noise_m_s2
        self.adaptive = bool(cfg.adaptive_meas_noise)
        self.gain_state = bool(cfg.estimate_input_gain)
        self.noise_min = cfg.meas_noise_m
        self.noise_max = max(cfg.meas_noise_max_m, cfg.meas_noise_m)
        low, high = cfg.input_gain_bounds
        self.gain_var_max = ((high - low) / 4.0) ** 2
        # R per ball: the configured noise, or (a fixed filter, as the benchmark's fast mode
        # runs it) the larger of it and the ball's own detection noise
        r0 = np.full(batch, cfg.meas_noise_m) if fixed_meas_noise_m is None or self.adaptive \
            else np.maximum(cfg.meas_noise_m, fixed_meas_noise_m)
        self.r = r0 ** 2
        # d (BallKalman's disturbance state): a random walk of jerk density q_d, its value kept
        # over dropped tracks; the change test, a window per ball (disturbance.ChangeTest)
        self.disturbance_state = cfg.disturbance_time_constant_s > 0.0
        self.dim = D_INDEX + 2 if self.disturbance_state else D_INDEX
        self.q_d = (cfg.cmd_accel_noise_m_s2 / cfg.disturbance_time_constant_s) ** 2 if self.disturbance_state else 0.0
        self.saved_d = np.zeros((batch, 2))
        self.saved_d_var = np.zeros(batch)
        self.transition = np.broadcast_to(np.eye(self.dim), (batch, self.dim, self.dim)).copy()
        self.track_start = np.zeros(batch)
        self.window = ChangeTest(batch, self.dim, D_INDEX, consistency_settle_s(cfg.model_mismatch_time_constant_s))
        self.disturbance_changes = np.zeros(batch, int)
        self.x = np.zeros((batch, self.dim))
        self.p = np.zeros((batch, self.dim, self.dim))
        self.saved_gain = np.ones(batch)
        self.saved_gain_var = np.full(batch, cfg.input_gain_std ** 2 if self.gain_state else 0.0)
        self.init = np.zeros(batch, bool)
        self.t_last = np.zeros(batch)
        self.coasted = np.zeros(batch, int)
        self.nis = np.ones(batch)
        self.noise = DetectionNoiseEstimator(cfg.meas_noise_window_frames, noise_min_samples, window_max_span_s, batch)

    @property
    def gain(self) -> np.ndarray:
        """s per ball (the saved estimate between tracks)."""
        return np.where(self.init, self.x[:, 4], self.saved_gain) if self.gain_state else np.ones(self.b)

    @property
    def disturbance_m_s2(self) -> np.ndarray:
        """d per ball (b, 2) [m/s^2] (the saved estimate between tracks; 0 without the state)."""
        if not self.disturbance_state:
            return np.zeros((self.b, 2))
        return np.where(self.init[:, None], self.x[:, D_INDEX:D_INDEX + 2], self.saved_d)

    def level_offset_rad(self, k_g: float) -> np.ndarray:
        """d as a plate-level offset per ball and axis (b, 2) [rad] (BallKalman.level_offset_rad)."""
        scale = (self.gain * k_g)[:, None]
        return np.arcsin(np.clip(self.disturbance_m_s2 / scale, -1.0, 1.0))

    def _reset(self, mask) -> None:
        if self.gain_state:
            self.saved_gain = np.where(mask & self.init, self.x[:, 4], self.saved_gain)
            self.saved_gain_var = np.where(mask & self.init, self.p[:, 4, 4], self.saved_gain_var)
        if self.disturbance_state:
            self.saved_d = np.where((mask & self.init)[:, None], self.x[:, D_INDEX:D_INDEX + 2], self.saved_d)
            self.saved_d_var = np.where(mask & self.init, self.p[:, D_INDEX, D_INDEX], self.saved_d_var)
            self.window.clear(mask)
        self.init &= ~mask
        self.coasted[mask] = 0
        self.excess_count[mask] = 0

    def _adapt_noise(self, t, z, a, det) -> None:
        """BallKalman._adapt_noise for the balls with a detection `det`."""
        self.noise.add(t, z, None if a is None else a * self.gain[:, None], det)
        sigma = self.noise.sigma(det)
        ready = np.isfinite(sigma)
        self.r[ready] = np.clip(sigma[ready], self.noise_min, self.noise_max) ** 2

    def step(self, t: float, z: np.ndarray, det: np.ndarray, accel=None, lever=None):
        """Frame at stamp t: detections z (b, 2) where det (b,) is set (the others are not
        stepped: a dropped frame, as the benchmark's fast mode skips it); accel (b, 2) the known
        acceleration or None; lever (b, 2) the tilt's lever offset (BallKalman.step) or None.
        Returns (position (b, 2), velocity (b, 2), valid (b,)) after it."""
        pos, vel, valid = self._step(t, z if lever is None else z - lever, det, accel)
        if lever is not None:   # tracked the detections less the lever, reported with it
            pos = pos + lever
        if self.fast is not None:   # after a push: the constant-velocity filter's velocity
            self.fast.r = self.r.copy()
            _, fast_vel, fast_valid = self.fast.step(t, z, det)
            use = valid & fast_valid & (t <= self.hold_until)
            vel[use] = fast_vel[use]
        return pos, vel, valid

    def _step(self, t: float, z: np.ndarray, det: np.ndarray, accel=None):
        if self.adaptive:
            self._adapt_noise(t, z, accel, det)
        dt = np.where(self.init, t - self.t_last, 0.0)
        self._reset(det & self.init & (dt > self.cfg.max_dt_s))
        pred = det & self.init & (dt > 0.0)
        if pred.any():
            self._predict(pred, np.where(pred, dt, 0.0), accel, holding=t <= self.hold_until)
            self.t_last = np.where(pred, t, self.t_last)
        start = det & ~self.init
        if start.any():
            i = np.flatnonzero(start)
            self.x[i] = 0.0
            self.x[i, :2] = z[i]
            self.x[i, 4] = self.saved_gain[i] if self.gain_state else 1.0
            self.p[i] = 0.0
            self.p[i, 0, 0] = self.p[i, 1, 1] = self.r[i]
            self.p[i, 2, 2] = self.p[i, 3, 3] = self.cfg.init_vel_std_m_s ** 2
            self.p[i, 4, 4] = self.saved_gain_var[i]
            if self.disturbance_state:
                self.x[i, D_INDEX:D_INDEX + 2] = self.saved_d[i]
                self.p[i, D_INDEX, D_INDEX] = self.p[i, D_INDEX + 1, D_INDEX + 1] = self.saved_d_var[i]
                self.transition[i] = np.eye(self.dim)
                self.track_start[i] = t
            self.init[i], self.coasted[i], self.t_last[i] = True, 0, t
        run = det & self.init & ~start
        valid = start.copy()
        if run.any():
            p, r = self.p, self.r
            y = z - self.x[:, :2]
            inv, distance = self._innovation(y)
            if self.maneuver_sigma > 0.0:
                seen = run & (dt > 0.0)
                widen, nis = seen & (distance > self.maneuver_sigma), self.nis
                if self.cfg.maneuver_confirm_frames > 1:
                    widen, nis = self._confirmed_pushes(seen, widen, y, distance)
                self.hold_until = np.where(widen & (nis <= MODEL_AGREED_NIS), t + self.cfg.maneuver_hold_s,
                                           self.hold_until)
                if widen.any() and self._widen(widen):
                    inv, widened_distance = self._innovation(y)
                    distance = np.where(widen, widened_distance, distance)
            gate = self.cfg.gate_sigma
            if self.cfg.model_mismatch_time_constant_s > 0.0:
                alpha = np.minimum(1.0, dt / self.cfg.model_mismatch_time_constant_s)
                self.nis = np.where(run, self.nis + alpha * (np.minimum(distance, gate) ** 2 / 2.0 - self.nis),
                                    self.nis)
            ok = run & (distance <= gate)
            if self.disturbance_state and ok.any():
                appended, changed = self._find_disturbance_change(t, ok, y, accel is not None)
                if changed:                   # a change found corrected the state
                    y = z - self.x[:, :2]
                    inv, _ = self._innovation(y)
            if ok.any():
                i = np.flatnonzero(ok)
                k = np.einsum("bij,bjk->bik", p[i, :, :2], inv[i])            # P H^T S^-1
                x_new = self.x[i] + np.einsum("bij,bj->bi", k, y[i])
                ikh = np.broadcast_to(np.eye(self.dim), (len(i), self.dim, self.dim)).copy()
                ikh[:, :, :2] -= k
                p_new = ikh @ p[i] @ ikh.transpose(0, 2, 1) + r[i, None, None] * (k @ k.transpose(0, 2, 1))
                if self.gain_state:
                    low, high = self.cfg.input_gain_bounds
                    x_new[:, 4] = np.clip(x_new[:, 4], low, high)
                self.x[i], self.p[i] = x_new, p_new
                self.coasted[i] = 0
                if self.disturbance_state:
                    self.window.set_last_gain(appended, k[np.isin(i, np.flatnonzero(appended))])
                    self.transition[i] = np.eye(self.dim)
            gated = run & ~ok
            self.coasted = np.where(gated, self.coasted + 1, self.coasted)
            lost = gated & (self.coasted > self.cfg.max_coast_frames)
            valid |= run & ~lost
            self._reset(lost)
        return self.x[:, :2].copy(), self.x[:, 2:4].copy(), valid

    def _find_disturbance_change(self, t: float, ok, y, known: bool):
        """BallKalman._find_disturbance_change for the balls `ok` (a detection within the gate,
        innovation y (b, 2)), before their update: returns the balls whose frame joined their
        window (their update's gain completes it) and whether any ball's state was corrected."""
        w = self.window
        if not known:
            w.clear(ok)
            return np.zeros(self.b, bool), False
        pushed = t <= self.hold_until
        w.clear(ok & pushed)
        add = ok & ~pushed
        if not add.any():
            return add, False
        s = self.p[:, :2, :2] + self.r[:, None, None] * np.eye(2)
        changed = w.test(t, add, y, s, self.nis, self.transition, self.track_start)
        for i in np.flatnonzero(changed):
            w.correct(i, t, self.x[i], self.p[i])
        self.disturbance_changes += changed
        return add & ~changed, bool(changed.any())

    def _confirmed_pushes(self, seen, beyond, y, distance):
        """BallKalman._push_seen for the balls with a detection `seen` (`beyond` maneuver_sigma):
        the balls whose detection shows a push, and the consistency to judge its hold by. Balls
        whose measurement noise is below maneuver_confirm_noise_m take one detection for a push."""
        single = self.r < self.cfg.maneuver_confirm_noise_m ** 2
        push_now, nis_now = self._confirmed_runs(seen & ~single, y, distance, beyond)
        self.excess_count = np.where(seen & single, 0, self.excess_count)   # a run in progress ends
        return np.where(single, beyond, push_now), np.where(single, self.nis, nis_now)

    def _confirmed_runs(self, seen, y, distance, beyond):
        """The runs of detections that make a push (maneuver_confirm_frames), for the balls `seen`."""
        goes_on = seen & (self.excess_count > 0) & (np.einsum("bi,bi->b", y, self.excess_y) > 0.0) \
            & (distance > self.cfg.maneuver_confirm_sigma)
        self.excess_nis = np.where(seen & ~goes_on, self.nis, self.excess_nis)
        self.excess_count = np.where(goes_on, self.excess_count + 1,
                                     np.where(seen, beyond.astype(int), self.excess_count))
        self.excess_y = np.where(seen[:, None], y, self.excess_y)
        push = seen & ((self.excess_count >= self.cfg.maneuver_confirm_frames) | (distance > self.cfg.gate_sigma))
        return push, self.excess_nis

    def _innovation(self, y: np.ndarray):
        """S^-1 (b, 2, 2) of the innovation y (b, 2) under the current P and R, and its
        Mahalanobis distance sqrt(y^T S^-1 y) (b,)."""
        p, r = self.p, self.r
        s00, s01, s11 = p[:, 0, 0] + r, p[:, 0, 1], p[:, 1, 1] + r
        det_s = s00 * s11 - s01 * s01
        inv = np.stack([np.stack([s11, -s01], -1), np.stack([-s01, s00], -1)], -2) / det_s[:, None, None]
        return inv, np.sqrt(np.maximum(np.einsum("bi,bij,bj->b", y, inv, y), 0.0))

    def _widen(self, mask) -> bool:
        """BallKalman._widen_last_prediction for the balls in mask (a push the commanded tilt does
        not explain): the last prediction's missing process noise."""
        h = self.last_dt
        extra = np.maximum(self.sigma_a ** 2 - self.last_q, 0.0)
        mask = mask & (h > 0.0) & (extra > 0.0)
        if not mask.any():
            return False
        i = np.flatnonzero(mask)
        p = self.p[i]
        add_white_acceleration(p, extra[i], h[i])
        self.p[i] = p
        return True

    def _predict(self, mask, dt, accel, holding) -> None:
        """BallKalman._predict for the balls in mask, dt (b,) their time steps; holding (b,) the
        balls in a maneuver hold: the same F and Q (vision/kalman.py prediction)."""
        i = np.flatnonzero(mask)
        h = dt[i]
        known = accel is not None
        q = process_noise(self.nis[i], known, holding[i], self.cfg)
        self.last_dt[i], self.last_q[i] = h, q
        f, qm = prediction(h, q, accel[i] if known else None, self.dim, 4,
                           self.cfg.input_gain_rate_per_s if self.gain_state else 0.0,
                           D_INDEX if self.disturbance_state else None, self.q_d)
        if self.disturbance_state:
            self.transition[i] = f @ self.transition[i]
        self.x[i] = np.einsum("bij,bj->bi", f, self.x[i])
        p = f @ self.p[i] @ f.transpose(0, 2, 1) + qm
        if self.gain_state:
            p[:, 4, 4] = np.minimum(p[:, 4, 4], self.gain_var_max)
        self.p[i] = p
