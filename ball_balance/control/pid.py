"""Per-axis PID on the plate-frame ball error (DESIGN.md section 6, step 2).

Sign: the plant is x'' = -k g u, so a ball on the +x side of its reference needs u_x > 0
(positive gains push it back). With e = x - r and the derivative taken from the measured
(Kalman) velocity rather than a differentiated error, per axis:

    u = kp e + ki integral(e) + kd (v - v_ref) + u_ff,    u_ff = -a_ref / (k g)

clipped to +-u_max. Anti-windup: conditional integration (the integral does not grow while
the output is saturated in the direction of the error) plus back-calculation (the integral
bleeds off by (u_sat - u_raw) / (ki * t_aw) while saturated), and a hard clamp |ki I| <= i_limit.
A deadband around zero error stops the integral from hunting on tracker noise, and the
integral only runs inside an error zone (|e| < i_zone_m): large moves are left to P and D.
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class PidGains:
    kp: float = 1.6                 # rad per m of error
    ki: float = 0.4                 # rad per (m s)
    kd: float = 0.9                 # rad per (m/s)
    u_max_rad: float = 0.15         # output clip (tilt)
    i_limit_rad: float = 0.03       # clamp on the integral's contribution ki*I
    deadband_m: float = 0.001       # |e| below this counts as zero for P and I
    i_zone_m: float = 0.02          # integrate only while |e| < i_zone (no wind-up on big moves)
    antiwindup_time_s: float = 0.2  # back-calculation time constant t_aw


class AxisPid:
    """One plate axis. `step` is allocation-free; `reset` clears the integral."""

    def __init__(self, gains: PidGains, k_g: float):
        self.gains = gains
        self.k_g = k_g              # k * g [m/s^2 per rad], for acceleration feed-forward
        self.integral = 0.0         # integral of the error [m s]
        self.saturated = False      # last output was clipped

    def reset(self) -> None:
        self.integral = 0.0
        self.saturated = False

    def step(self, error_m: float, vel_error_m_s: float, acc_ref_m_s2: float, dt_s: float) -> float:
        """One update. error_m = x - r, vel_error_m_s = v - v_ref. Returns u [rad], clipped."""
        g = self.gains
        e = 0.0 if abs(error_m) < g.deadband_m else error_m - math.copysign(g.deadband_m, error_m)
        u_ff = -acc_ref_m_s2 / self.k_g
        u_pd = g.kp * e + g.kd * vel_error_m_s + u_ff
        # Integrate unless the output is saturated and the error would push it further.
        candidate = self.integral + (e * dt_s if abs(e) < g.i_zone_m else 0.0)
        u_raw = u_pd + g.ki * candidate
        pushing_out = (u_raw > g.u_max_rad and e > 0) or (u_raw < -g.u_max_rad and e < 0)
        if not pushing_out:
            self.integral = candidate
        if g.ki > 0:
            i_max = g.i_limit_rad / g.ki
            self.integral = min(max(self.integral, -i_max), i_max)
        u_raw = u_pd + g.ki * self.integral
        u = min(max(u_raw, -g.u_max_rad), g.u_max_rad)
        self.saturated = u != u_raw
        if self.saturated and g.ki > 0 and g.antiwindup_time_s > 0:
            # back-calculation: drive the integral toward the value that would just saturate
            self.integral += (u - u_raw) / (g.ki * g.antiwindup_time_s) * dt_s
            self.integral = min(max(self.integral, -i_max), i_max)
        return u


class PlatePid:
    """Two independent axes (x -> u_x, y -> u_y) sharing one gain set."""

    def __init__(self, gains: PidGains, k_g: float):
        self.axes = (AxisPid(gains, k_g), AxisPid(gains, k_g))

    def set_gains(self, gains: PidGains) -> None:
        for axis in self.axes:
            axis.gains = gains

    def reset(self) -> None:
        for axis in self.axes:
            axis.reset()

    def step(self, pos_m, vel_m_s, ref, dt_s: float):
        """pos/vel: measured (predicted) ball state, ref: RefSample. Returns (u_x, u_y) [rad]."""
        return tuple(axis.step(pos_m[i] - ref.p[i], vel_m_s[i] - ref.v[i], ref.a[i], dt_s)
                     for i, axis in enumerate(self.axes))
