"""Constant-velocity Kalman filter of the ball in the plate frame (filterpy).

State x = [x, y, vx, vy] (m, m/s); measurement z = [x, y] (m). Per frame, with the
time step dt from the frame stamps:

    F = [[I, dt I], [0, I]]                 constant velocity
    B = [[dt^2/2 I], [dt I]],  u = a        optional known acceleration (from the tilt)
    Q = q [[dt^4/4 I, dt^3/2 I], [dt^3/2 I, dt^2 I]],  q = sigma_a^2   white-noise acceleration
    H = [I 0],  R = sigma_z^2 I

A detection whose Mahalanobis distance sqrt(y^T S^-1 y) exceeds `gate_sigma` is ignored
(an outlier). Without a usable detection the filter coasts (predicts) for up to
`max_coast_frames` frames, still valid; then the track is dropped and the next detection
starts a new one. A gap longer than `max_dt_s` also drops the track.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np
from filterpy.kalman import KalmanFilter


@dataclass(frozen=True)
class TrackEstimate:
    x: float
    y: float
    vx: float
    vy: float
    fresh: bool          # this frame's detection was used (ball_found)
    valid: bool          # a usable estimate (fresh or coasting)
    gated: bool = False  # a detection was rejected as an outlier


class BallKalman:
    """Tracks one ball; `step()` once per frame with the frame's stamp."""

    def __init__(self, meas_noise_m: float = 0.001, accel_noise_m_s2: float = 1.0, init_vel_std_m_s: float = 0.5,
                 gate_sigma: float = 6.0, max_coast_frames: int = 5, max_dt_s: float = 0.5):
        self.sigma_a = accel_noise_m_s2
        self.init_vel_std = init_vel_std_m_s
        self.gate_sigma = gate_sigma
        self.max_coast_frames = max_coast_frames
        self.max_dt_s = max_dt_s
        kf = KalmanFilter(dim_x=4, dim_z=2, dim_u=2)
        kf.H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])   # z = H x
        kf.R = np.eye(2) * meas_noise_m ** 2                                 # measurement noise
        self.kf = kf
        self.initialised = False
        self.coasted = 0              # frames predicted without a detection since the last one
        self.t_last: Optional[float] = None
        self.gated_count = 0          # detections rejected as outliers (total)
        self.reset_count = 0          # tracks dropped (total)

    def reset(self) -> None:
        """Drop the track: the next detection starts a new one."""
        if self.initialised:
            self.reset_count += 1
        self.initialised = False
        self.coasted = 0
        self.t_last = None

    def _start(self, z: Tuple[float, float], t: float) -> None:
        kf = self.kf
        kf.x = np.array([z[0], z[1], 0.0, 0.0])
        kf.P = np.diag([kf.R[0, 0], kf.R[1, 1], self.init_vel_std ** 2, self.init_vel_std ** 2])
        self.initialised, self.coasted, self.t_last = True, 0, t

    def _predict(self, dt: float, accel: Optional[Tuple[float, float]]) -> None:
        kf = self.kf
        I2 = np.eye(2)
        kf.F = np.block([[I2, dt * I2], [0 * I2, I2]])
        q = self.sigma_a ** 2
        kf.Q = q * np.block([[dt ** 4 / 4 * I2, dt ** 3 / 2 * I2], [dt ** 3 / 2 * I2, dt ** 2 * I2]])
        if accel is None:
            kf.predict()
        else:
            kf.B = np.block([[dt ** 2 / 2 * I2], [dt * I2]])
            kf.predict(u=np.asarray(accel, dtype=np.float64))

    def mahalanobis(self, z: Tuple[float, float]) -> float:
        """Distance of z from the predicted measurement, in standard deviations."""
        kf = self.kf
        y = np.asarray(z) - kf.H @ kf.x                    # innovation
        S = kf.H @ kf.P @ kf.H.T + kf.R                    # innovation covariance
        return float(np.sqrt(y @ np.linalg.solve(S, y)))

    def step(self, t: float, z: Optional[Tuple[float, float]],
             accel: Optional[Tuple[float, float]] = None) -> TrackEstimate:
        """Advance to stamp t (s) and fold in detection z (m) if any; accel in m/s^2 or None."""
        if self.initialised:
            dt = t - self.t_last
            if dt > self.max_dt_s:
                self.reset()
            elif dt > 0.0:            # a repeated or out-of-order stamp only updates
                self._predict(dt, accel)
                self.t_last = t
        if not self.initialised:
            if z is None:
                return self._estimate(fresh=False, valid=False)
            self._start(z, t)
            return self._estimate(fresh=True, valid=True)
        gated = False
        if z is not None:
            if self.mahalanobis(z) <= self.gate_sigma:
                self.kf.update(np.asarray(z, dtype=np.float64))
                self.coasted = 0
                return self._estimate(fresh=True, valid=True)
            gated = True
            self.gated_count += 1
        self.coasted += 1
        if self.coasted > self.max_coast_frames:
            estimate = self._estimate(fresh=False, valid=False, gated=gated)
            self.reset()
            return estimate
        return self._estimate(fresh=False, valid=True, gated=gated)

    def _estimate(self, fresh: bool, valid: bool, gated: bool = False) -> TrackEstimate:
        """The current state; an invalid estimate keeps the last position with zero velocity
        (all zeros before the first track)."""
        x = np.ravel(self.kf.x)
        if not valid:
            return TrackEstimate(float(x[0]), float(x[1]), 0.0, 0.0, fresh, False, gated)
        return TrackEstimate(float(x[0]), float(x[1]), float(x[2]), float(x[3]), fresh, valid, gated)
