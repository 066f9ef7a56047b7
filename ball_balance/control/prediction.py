"""Latency compensation: predict the ball state forward over the measured delay.

The tracker stamps each state with the camera capture time. Between that instant and the
moment a new command reaches the plate, the plate keeps the tilts that were commanded
earlier; `TiltHistory` remembers them, and `predict` integrates the plant
x'' = -k g u(t - actuation_delay) exactly over piecewise-constant tilt segments.
"""
from __future__ import annotations

from collections import deque
from typing import Deque, Tuple

import numpy as np


class TiltHistory:
    """Commanded tilts (u_x, u_y) [rad] with the controller time [s] they were issued at."""

    def __init__(self, max_len: int = 256):
        self._entries: Deque[Tuple[float, float, float]] = deque(maxlen=max_len)

    def clear(self) -> None:
        self._entries.clear()

    def record(self, t_s: float, u_x: float, u_y: float) -> None:
        self._entries.append((t_s, u_x, u_y))

    def at(self, t_s: float) -> Tuple[float, float]:
        """The tilt in force at time t_s (latest command issued at or before t_s; 0 before any)."""
        u = (0.0, 0.0)
        for t_i, ux, uy in self._entries:
            if t_i > t_s:
                break
            u = (ux, uy)
        return u

    def breakpoints(self, t0_s: float, t1_s: float):
        """Times of command changes strictly inside (t0_s, t1_s)."""
        return [t_i for t_i, _, _ in self._entries if t0_s < t_i < t1_s]


def predict(pos_m: np.ndarray, vel_m_s: np.ndarray, t_from_s: float, t_to_s: float,
            history: TiltHistory, k_g: float, actuation_delay_s: float = 0.0):
    """State (pos, vel) [m, m/s], shape (2,), propagated from t_from_s to t_to_s.

    The plate tilt acting at time t is the command issued at t - actuation_delay_s.
    Returns new arrays; when t_to_s <= t_from_s the state is returned unchanged.
    """
    p = np.array(pos_m, dtype=float)
    v = np.array(vel_m_s, dtype=float)
    if not t_to_s > t_from_s:
        return p, v
    # Segment boundaries: command changes shifted by the actuation delay.
    cuts = [t + actuation_delay_s for t in history.breakpoints(t_from_s - actuation_delay_s,
                                                                 t_to_s - actuation_delay_s)]
    times = [t_from_s, *cuts, t_to_s]
    for t0, t1 in zip(times[:-1], times[1:], strict=False):
        h = t1 - t0
        # a = -k g u, constant over the segment
        a = -k_g * np.asarray(history.at(t0 - actuation_delay_s + 1e-12))
        p += v * h + 0.5 * a * h * h
        v += a * h
    return p, v
