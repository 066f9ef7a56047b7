"""Per-axis PID on the plate-frame ball error (docs/design.md section 6, step 4).

Sign: the plant is x'' = -k g u, so a ball on the +x side of its reference needs u_x > 0
(positive gains push it back). With e = x - r and the derivative taken from the measured
(Kalman) velocity rather than a differentiated error, per axis:

    u = kp e + ki integral(e) + kd (v - v_ref) + u_ff,    u_ff = -a_ref / (k g)

clipped to +-u_max. Anti-windup: conditional integration (the integral does not grow while
the output is saturated in the direction of the error) plus back-calculation (while
saturated, the part of the integral that pushes into the limit bleeds off at
(u_raw - u_sat) / (ki * t_aw)), and a hard clamp |ki I| <= i_limit. Back-calculation only
unwinds: it moves the integral toward zero and stops there, never charging it against the
error (a saturation caused by P and D on a big error would otherwise drive the integral to
its opposite clamp within ~0.1 s, leaving the ball 10-15 mm off target for seconds). A
deadband around zero error stops the integral from hunting on tracker noise, and the
integral only changes inside an error zone (|e| < i_zone_m): outside it, large moves are
left to P and D and the integral is held, by integration and back-calculation alike. Nor
does it grow while the ball moves off the reference's speed (|v - v_ref| >= i_max_vel_error_m_s,
the D term's filtered velocity error): the integral is for a constant offset, which shows
as an error at the reference's speed; a ball returning from a push crosses the zone at
0.1 m/s and, integrated, the return charged it enough to carry the ball 5 mm past the target.
The D term's velocity error passes a first-order low-pass (`derivative_filter_s`): the
tracker's Kalman velocity is noisy enough that, unfiltered, it shook the plate (tilt-rate
RMS 3x the MPC's), pulled the online plant estimate off through the loop and cost
1-2 mm on the circle and 0.3-0.7 s of push recovery (docs/control.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class PidGains:
    kp: float = 2.0                 # rad per m of error
    ki: float = 0.4                 # rad per (m s)
    kd: float = 0.75                # rad per (m/s)
    u_max_rad: float = 0.15         # output clip (tilt)
    i_limit_rad: float = 0.03       # clamp on the integral's contribution ki*I
    deadband_m: float = 0.0         # |e| below this counts as zero for P and I (0: off)
    i_zone_m: float = 0.02          # integrate only while |e| < i_zone (no wind-up on big moves)
    antiwindup_time_s: float = 0.2  # back-calculation time constant t_aw
    derivative_filter_s: float = 0.06  # first-order low-pass on v - v_ref for the D term (0: off)
    i_max_vel_error_m_s: float = 0.03  # integrate only while |v - v_ref| is below this (0: off)


class AxisPid:
    """One plate axis. `step` is allocation-free; `reset` clears the integral."""

    def __init__(self, gains: PidGains, k_g: float):
        self.gains = gains
        self.k_g = k_g              # k * g [m/s^2 per rad], for acceleration feed-forward
        self.integral = 0.0         # integral of the error [m s]
        self.saturated = False      # last output was clipped
        self.vel_error_filtered: float | None = None   # D term's input after the low-pass

    def reset(self) -> None:
        self.integral = 0.0
        self.saturated = False
        self.vel_error_filtered = None

    def step(self, error_m: float, vel_error_m_s: float, acc_ref_m_s2: float, dt_s: float,
             gain_scale: float = 1.0, u_bias_rad: float = 0.0) -> float:
        """One update. error_m = x - r, vel_error_m_s = v - v_ref. Returns u [rad], clipped.

        gain_scale multiplies the feedback (P, I, D) only, e.g. k_g (configured) / k_g (estimated)
        to keep the loop's acceleration per metre of error on a stronger plant; u_bias_rad = d / k_g
        cancels an estimated constant disturbance (control/estimation.py). The caller passes the
        reference acceleration scaled to the plant gain it believes in. 1 and 0 without an estimate.
        """
        g = self.gains
        e = 0.0 if abs(error_m) < g.deadband_m else error_m - math.copysign(g.deadband_m, error_m)
        u_ff = -acc_ref_m_s2 / self.k_g
        if g.derivative_filter_s > 0.0 and self.vel_error_filtered is not None:
            alpha = dt_s / (g.derivative_filter_s + dt_s)
            vel_error_m_s = self.vel_error_filtered + alpha * (vel_error_m_s - self.vel_error_filtered)
        self.vel_error_filtered = vel_error_m_s
        u_pd = gain_scale * (g.kp * e + g.kd * vel_error_m_s) + u_ff + u_bias_rad
        # Integrate near the reference's speed, unless the output is saturated and the error
        # would push it further.
        settled = g.i_max_vel_error_m_s <= 0.0 or abs(vel_error_m_s) < g.i_max_vel_error_m_s
        candidate = self.integral + (e * dt_s if abs(e) < g.i_zone_m and settled else 0.0)
        u_raw = u_pd + gain_scale * g.ki * candidate
        pushing_out = (u_raw > g.u_max_rad and e > 0) or (u_raw < -g.u_max_rad and e < 0)
        if not pushing_out:
            self.integral = candidate
        if g.ki > 0:
            i_max = g.i_limit_rad / g.ki
            self.integral = min(max(self.integral, -i_max), i_max)
        u_raw = u_pd + gain_scale * g.ki * self.integral
        u = min(max(u_raw, -g.u_max_rad), g.u_max_rad)
        self.saturated = u != u_raw
        if self.saturated and g.ki > 0 and g.antiwindup_time_s > 0 and abs(e) < g.i_zone_m:
            # back-calculation: unwind only the integral that pushes into the limit, to zero at most
            into_limit = math.copysign(1.0, u_raw - u)
            if self.integral * into_limit > 0:
                bleed = abs(u_raw - u) / (gain_scale * g.ki * g.antiwindup_time_s) * dt_s
                self.integral = into_limit * max(0.0, abs(self.integral) - bleed)
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

    def step(self, pos_m, vel_m_s, ref, dt_s: float, gain_scale: float = 1.0, u_bias_rad=(0.0, 0.0)):
        """pos/vel: measured (predicted) ball state, ref: RefSample. Returns (u_x, u_y) [rad]."""
        return tuple(axis.step(pos_m[i] - ref.p[i], vel_m_s[i] - ref.v[i], ref.a[i], dt_s, gain_scale,
                               float(u_bias_rad[i]))
                     for i, axis in enumerate(self.axes))
