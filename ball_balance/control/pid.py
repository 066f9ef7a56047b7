"""Per-axis PID on the plate-frame ball error (docs/design.md section 6, step 4).

Sign: the plant is x'' = -k g u, so a ball on the +x side of its reference needs u_x > 0
(positive gains push it back). With e = x - r and the derivative taken from the measured
(Kalman) velocity rather than a differentiated error, per axis:

    u = kp e + ki integral(e) + kd (v - v_ref) + u_ff,    u_ff = -a_ref / (k g)

clipped to +-u_max. The integral is off by default (ki 0): the tracker's disturbance state,
cancelled through u_bias_rad, is what removes a constant offset (docs/control.md). With
ki > 0 it has the usual anti-windup: conditional integration (it does not grow while the
output is saturated in the direction of the error), back-calculation (while saturated, the
part of the integral that pushes into the limit bleeds off at (u_raw - u_sat) / (ki * t_aw),
toward zero and no further, never charging it against the error) and a clamp
|ki I| <= i_limit. The D term's velocity error passes a first-order low-pass
(`derivative_filter_s`): the tracker's Kalman velocity is noisy enough that, unfiltered, it
shakes the plate, pulls the online plant estimate off through the loop and costs tracking
accuracy and push recovery (docs/control.md).

The law is written once, over arrays (`Pid`): every element is an independent axis, a
plate's two at run time (`PlatePid`), a batch of plates' in the training plant
(ball_balance/policy/env.py).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np


@dataclass(frozen=True)
class PidGains:
    kp: float = 2.0                 # rad per m of error
    ki: float = 0.0                 # rad per (m s); 0: the tracker's disturbance state holds the offset
    kd: float = 0.75                # rad per (m/s)
    u_max_rad: float = 0.15         # output clip (tilt)
    i_limit_rad: float = 0.03       # clamp on the integral's contribution ki*I
    antiwindup_time_s: float = 0.2  # back-calculation time constant t_aw
    derivative_filter_s: float = 0.06  # first-order low-pass on v - v_ref for the D term (0: off)


class Pid:
    """The law over an array of independent axes of `shape` sharing one gain set: () one
    axis, (2,) a plate, (batch, 2) a batch of plates. `reset` clears the integral and the
    derivative filter."""

    def __init__(self, gains: PidGains, k_g: float, shape: Tuple[int, ...] = ()):
        self.gains = gains
        self.k_g = k_g                  # k * g [m/s^2 per rad], for acceleration feed-forward
        self.shape = tuple(shape)
        self.integral = np.zeros(self.shape)        # integral of the error [m s]
        self.saturated = np.zeros(self.shape, bool)  # last output was clipped
        self.vel_error_filtered: Optional[np.ndarray] = None   # D term's input after the low-pass

    def reset(self) -> None:
        self.integral = np.zeros(self.shape)
        self.saturated = np.zeros(self.shape, bool)
        self.vel_error_filtered = None

    def step(self, error_m, vel_error_m_s, acc_ref_m_s2, dt_s: float, gain_scale=1.0,
             u_bias_rad=0.0) -> np.ndarray:
        """One update of every axis. error_m = x - r, vel_error_m_s = v - v_ref, acc_ref_m_s2:
        arrays of the law's shape (or broadcasting to it). Returns u [rad], clipped.

        gain_scale multiplies the feedback (P, I, D) only, e.g. k_g (configured) / k_g (estimated)
        to keep the loop's acceleration per metre of error on a stronger plant; u_bias_rad = d / k_g
        cancels an estimated constant disturbance (control/estimation.py). The caller passes the
        reference acceleration scaled to the plant gain it believes in. 1 and 0 without an
        estimate; either may be an array broadcasting to the law's shape.
        """
        g = self.gains
        e = np.asarray(error_m, dtype=float)
        vel_error = np.array(vel_error_m_s, dtype=float)
        if g.derivative_filter_s > 0.0 and self.vel_error_filtered is not None:
            alpha = dt_s / (g.derivative_filter_s + dt_s)
            vel_error = self.vel_error_filtered + alpha * (vel_error - self.vel_error_filtered)
        self.vel_error_filtered = vel_error
        u_ff = np.asarray(acc_ref_m_s2, dtype=float) / -self.k_g
        u_pd = gain_scale * (g.kp * e + g.kd * vel_error) + u_ff + u_bias_rad
        if g.ki <= 0.0:
            u = np.minimum(np.maximum(u_pd, -g.u_max_rad), g.u_max_rad)
            self.saturated = u != u_pd
            return u
        k_i = gain_scale * g.ki
        # integrate, unless the output is saturated and the error would push it further
        candidate = self.integral + e * dt_s
        u_raw = u_pd + k_i * candidate
        pushing_out = np.sign(e) * u_raw > g.u_max_rad   # past the limit on the error's side
        integral = np.where(pushing_out, self.integral, candidate)
        i_max = g.i_limit_rad / g.ki
        integral = np.minimum(np.maximum(integral, -i_max), i_max)
        u_raw = u_pd + k_i * integral
        u = np.minimum(np.maximum(u_raw, -g.u_max_rad), g.u_max_rad)
        self.saturated = u != u_raw
        if g.antiwindup_time_s > 0 and np.count_nonzero(self.saturated):
            # back-calculation: unwind only the integral that pushes into the limit, to zero at most
            into_limit = np.sign(u_raw - u)
            unwind = self.saturated & (integral * into_limit > 0)
            bleed = np.abs(u_raw - u) / (k_i * g.antiwindup_time_s) * dt_s
            integral = np.where(unwind, into_limit * np.maximum(0.0, np.abs(integral) - bleed), integral)
        self.integral = integral
        return u


class PlatePid:
    """A plate's two axes (x -> u_x, y -> u_y) sharing one gain set, stepped on the ball state
    and a reference sample."""

    def __init__(self, gains: PidGains, k_g: float):
        self.law = Pid(gains, k_g, (2,))

    @property
    def gains(self) -> PidGains:
        return self.law.gains

    def set_gains(self, gains: PidGains) -> None:
        self.law.gains = gains

    def reset(self) -> None:
        self.law.reset()

    def step(self, pos_m, vel_m_s, ref, dt_s: float, gain_scale: float = 1.0,
             u_bias_rad=(0.0, 0.0)) -> Tuple[float, float]:
        """pos/vel: measured (predicted) ball state, ref: RefSample. Returns (u_x, u_y) [rad]."""
        u = self.law.step(np.subtract(pos_m, ref.p), np.subtract(vel_m_s, ref.v), ref.a, dt_s, gain_scale,
                          u_bias_rad)
        return float(u[0]), float(u[1])
