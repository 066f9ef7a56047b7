"""Disturbance observer: a Kalman filter of the ball per plate axis whose state includes the
constant (or slowly varying) disturbance acceleration d, so that control with it is offset-free.

Per axis, with u(t) the plate tilt the ball feels (measured, from /joint_states) and the plant
gain k_g in use,

    p'' = -k_g u(t) + d,        d' = w_d (white, spectral density q_d),

plus white acceleration noise w_a (q_a) for what the model leaves out (friction, the gain's
error, the tilt's measurement). Over the interval dt between two ball states the input's
contribution (its double and single integral, Pi and Vi) is known exactly, so

    p' = p + v dt + d dt^2/2 + Pi,     v' = v + d dt + Vi,     d' = d
    F  = [[1, dt, dt^2/2], [0, 1, dt], [0, 0, 1]]
    Q  = q_a [[dt^3/3, dt^2/2, 0], [dt^2/2, dt, 0], [0, 0, 0]]
       + q_d [[dt^5/20, dt^4/8, dt^3/6], [dt^4/8, dt^3/3, dt^2/2], [dt^3/6, dt^2/2, dt]]

and the measurement is the tracked position, z = p + n, n ~ N(0, sigma_z^2). The two axes
share F, Q and R, so they share one covariance P (3 x 3) and one gain: the state is a 3 x 2
array, a column per axis.

The disturbance's noise q_d is not a tuning knob but the settling time the observer is built
for: with q_a small, a steady-state filter of this kind has its poles near the bandwidth
omega = (q_d / sigma_z^2)^(1/6), so q_d = sigma_z^2 omega^6 with omega = 1 / settle_time (a
step in d is then 90 % found after about two settling times). A larger q_a lets p and v take
up what d should, and slows that down.

sigma_z is what the positions really scatter by: the innovations' spread is P_pp + sigma_z^2,
so their running mean square, less P_pp, sets sigma_z^2 (never below `position_noise_m`).

A push (a hand, a knock: a velocity step the model did not see coming) is not a disturbance
acceleration. Its first detections lie far outside the predicted spread (beyond `gate_sigma`,
a chi-square gate on the innovation). For such a detection the prediction is re-made with a
white acceleration large enough to explain it, on position and velocity only: the update then
moves p and v, and d keeps its value, its covariance with them, and so nearly all of its
estimate. A constant force, by contrast, shows as a small innovation frame after frame and
moves d at the designed rate.
"""
from __future__ import annotations

import math
from typing import Optional, Sequence

import numpy as np


class DisturbanceObserver:
    """The filter above for one plate (two axes). Feed `step` with each new ball position and
    the input's contribution since the last one; `d` is the disturbance estimate [m/s^2]."""

    def __init__(self, position_noise_m: float, accel_noise_m_s2: float, settle_time_s: float,
                 max_disturbance_m_s2: float, gate_sigma: float = 4.0, max_gap_s: float = 0.2):
        self.r_min = self.r = position_noise_m ** 2
        self.q_a = accel_noise_m_s2 ** 2
        self.q_d = self.r / settle_time_s ** 6
        self._y2 = self.r                      # running mean of the squared innovation, per axis
        self.d_max = max_disturbance_m_s2
        self.gate_sigma = gate_sigma
        self.max_gap_s = max_gap_s
        self.x = np.zeros((3, 2))              # rows p [m], v [m/s], d [m/s^2]; a column per axis
        self.P = np.zeros((3, 3))
        # d's variance at the start: the whole range is plausible
        self._d_var = (max_disturbance_m_s2 / 2.0) ** 2
        self.t: Optional[float] = None
        self.pushes = 0                        # detections explained as a push (total)

    @property
    def d(self) -> np.ndarray:
        """The disturbance acceleration per axis [m/s^2]."""
        return self.x[2].copy()

    def reset(self) -> None:
        """Forget the ball's track (its position and velocity), keep the disturbance: the plate
        has not changed. The next position starts a new track."""
        if self.t is not None:
            self._d_var = float(self.P[2, 2])
        self.t = None

    def _start(self, t_s: float, pos_m: np.ndarray) -> None:
        d = self.x[2].copy()
        self.x = np.zeros((3, 2))
        self.x[0], self.x[2] = pos_m, d
        # the tracker's velocity is not used: an unknown velocity (0.3 m/s 1-sigma) takes two
        # frames to settle, and the first frames then say little about d
        self.P = np.diag([self.r, 0.3 ** 2, self._d_var])
        self.t = t_s

    @staticmethod
    def _accel_noise(dt: float, q_a: float) -> np.ndarray:
        """Q of a white acceleration of spectral density q_a over dt (on p and v)."""
        return q_a * np.array([[dt ** 3 / 3, dt ** 2 / 2, 0.0], [dt ** 2 / 2, dt, 0.0], [0.0, 0.0, 0.0]])

    def _process_noise(self, dt: float) -> np.ndarray:
        d = self.q_d * np.array([[dt ** 5 / 20, dt ** 4 / 8, dt ** 3 / 6],
                                 [dt ** 4 / 8, dt ** 3 / 3, dt ** 2 / 2],
                                 [dt ** 3 / 6, dt ** 2 / 2, dt]])
        return self._accel_noise(dt, self.q_a) + d

    def step(self, t_s: float, pos_m: Sequence[float], input_pos_m: Sequence[float],
             input_vel_m_s: Sequence[float]) -> np.ndarray:
        """Advance to stamp t_s and fold in the tracked position pos_m (2,). input_pos_m and
        input_vel_m_s (2,) are the double and single integral of -k_g u over the interval
        since the last step (ignored on the first). Returns d (2,)."""
        z = np.asarray(pos_m, dtype=float)
        if not np.all(np.isfinite(z)) or not math.isfinite(t_s):
            return self.d
        if self.t is not None and (t_s - self.t > self.max_gap_s or t_s < self.t):
            self.reset()
        if self.t is None:
            self._start(t_s, z)
            return self.d
        dt = t_s - self.t
        if dt <= 0.0:
            return self.d
        F = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
        x = F @ self.x
        x[0] += np.asarray(input_pos_m, dtype=float)
        x[1] += np.asarray(input_vel_m_s, dtype=float)
        P = F @ self.P @ F.T + self._process_noise(dt)
        y = z - x[0]
        s = P[0, 0] + self.r
        nis = float(y @ y) / s                     # both axes: chi-square with 2 degrees of freedom
        if nis <= self.gate_sigma ** 2:
            # covariance matching: the innovations' spread is P00 + R; what the positions really
            # scatter by sets R (never below position_noise_m), so a noisier tracker gets a slower
            # observer instead of passing its noise on as a disturbance
            self._y2 += min(1.0, dt / 2.0) * (0.5 * float(y @ y) - self._y2)
            self.r = max(self.r_min, self._y2 - P[0, 0])
            s = P[0, 0] + self.r
        if nis > self.gate_sigma ** 2:
            # a push: the acceleration that would explain this innovation, on p and v only
            self.pushes += 1
            q_push = float(np.max(np.abs(y))) ** 2 / (dt ** 3 / 3)
            P = P + self._accel_noise(dt, q_push)
            s = P[0, 0] + self.r
        k = P[:, 0] / s
        x += np.outer(k, y)
        P = P - np.outer(k, P[0])
        x[2] = np.clip(x[2], -self.d_max, self.d_max)
        self.x, self.P, self.t = x, 0.5 * (P + P.T), t_s
        return self.d
