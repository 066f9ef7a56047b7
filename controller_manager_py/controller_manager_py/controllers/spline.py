"""Cubic trajectory pieces (pure math, no ROS): Hermite segments and the clamped spline.

A segment from knot (t_0, p_0, v_0) to (t_1, p_1, v_1), with h = t_1 - t_0 and s = (t - t_0)/h:
    p(s) = h00(s) p_0 + h10(s) h v_0 + h01(s) p_1 + h11(s) h v_1
with the Hermite basis h00 = 2s^3 - 3s^2 + 1, h10 = s^3 - 2s^2 + s, h01 = -2s^3 + 3s^2,
h11 = s^3 - s^2. Position-only waypoints get their velocities from the clamped cubic
spline (continuous acceleration at interior knots), an O(n) tridiagonal solve:
    h_i v_{i-1} + 2 (h_{i-1} + h_i) v_i + h_{i-1} v_{i+1}
        = 3 (h_i (p_i - p_{i-1}) / h_{i-1} + h_{i-1} (p_{i+1} - p_i) / h_i),   0 < i < n-1
with v_0 and v_{n-1} given (the current velocity, and rest at the end).
"""
from __future__ import annotations

from typing import List, Sequence, Tuple


def hermite(t0: float, p0: float, v0: float, t1: float, p1: float, v1: float, t: float) -> Tuple[float, float, float]:
    """Position, velocity, acceleration at time t of the cubic through the two knots."""
    h = t1 - t0
    s = (t - t0) / h
    s2, s3 = s * s, s * s * s
    p = (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * h * v0 + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * h * v1
    # d/dt = (1/h) d/ds
    v = ((6 * s2 - 6 * s) * p0 + (3 * s2 - 4 * s + 1) * h * v0 + (-6 * s2 + 6 * s) * p1 + (3 * s2 - 2 * s) * h * v1) / h
    a = ((12 * s - 6) * p0 + (6 * s - 4) * h * v0 + (-12 * s + 6) * p1 + (6 * s - 2) * h * v1) / (h * h)
    return p, v, a


def clamped_spline_velocities(times: Sequence[float], positions: Sequence[float],
                              v_start: float, v_end: float) -> List[float]:
    """Knot velocities of the clamped cubic spline through (times, positions) (Thomas algorithm).

    times strictly increasing (s), positions in any unit; returns one velocity per knot.
    """
    n = len(times)
    if n < 2:
        return [v_start] * n
    v = [0.0] * n
    v[0], v[-1] = v_start, v_end
    m = n - 2  # unknowns v_1 .. v_{n-2}
    if m == 0:
        return v
    h = [times[i + 1] - times[i] for i in range(n - 1)]
    lower, diag, upper, rhs = [0.0] * m, [0.0] * m, [0.0] * m, [0.0] * m
    for k in range(m):
        i = k + 1
        lower[k], diag[k], upper[k] = h[i], 2.0 * (h[i - 1] + h[i]), h[i - 1]
        rhs[k] = 3.0 * (h[i] * (positions[i] - positions[i - 1]) / h[i - 1]
                        + h[i - 1] * (positions[i + 1] - positions[i]) / h[i])
    rhs[0] -= lower[0] * v_start
    rhs[-1] -= upper[-1] * v_end
    # forward elimination
    for k in range(1, m):
        w = lower[k] / diag[k - 1]
        diag[k] -= w * upper[k - 1]
        rhs[k] -= w * rhs[k - 1]
    # back substitution
    v[m] = rhs[m - 1] / diag[m - 1]
    for k in range(m - 2, -1, -1):
        v[k + 1] = (rhs[k] - upper[k] * v[k + 2]) / diag[k]
    return v
