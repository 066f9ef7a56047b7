"""Latency compensation: predict the ball state forward over the measured delay.

The tracker stamps each state with the camera capture time. Between that instant and the
moment a new command reaches the plate, the plate keeps the tilts that were commanded
earlier; `TiltHistory` remembers them, and `predict` integrates the plant
x'' = -k g u(t - actuation_delay) + d exactly over piecewise-constant tilt segments (k g and
the constant disturbance d: nominal, or the online estimate of control/estimation.py).
`predict_batch` is that law for a batch of plates (the training plant's, policy/env.py);
`predict` is a batch of one.
"""
from __future__ import annotations

import math
from bisect import bisect_left, bisect_right
from collections import deque
from typing import Callable, Deque, Tuple

import numpy as np


class TiltHistory:
    """Commanded tilts (u_x, u_y) [rad] with the controller time [s] they were issued at.

    Looked up by bisection (a prediction asks for a window of it every tick; a scan of a few
    hundred entries would be most of its cost). The times only go forward: a time
    before the last one (a clock reset) starts the history again."""

    def __init__(self, max_len: int = 256):
        self._times: Deque[float] = deque(maxlen=max_len)
        self._tilts: Deque[Tuple[float, float]] = deque(maxlen=max_len)   # (u_x, u_y) issued at _times

    def clear(self) -> None:
        self._times.clear()
        self._tilts.clear()

    def record(self, t_s: float, u_x: float, u_y: float) -> None:
        if self._times and t_s < self._times[-1]:
            self.clear()
        self._times.append(t_s)
        self._tilts.append((u_x, u_y))

    def acting(self, t0_s: float, t1_s: float) -> Tuple[np.ndarray, np.ndarray]:
        """The commands in force over (t0_s, t1_s): their issue times (n,) and tilts (n, 2),
        the one in force at t0_s first (issued at -inf with tilt 0 before any), then those
        issued strictly inside."""
        first, end = bisect_right(self._times, t0_s), bisect_left(self._times, t1_s)
        start = max(first - 1, 0)
        times = [self._times[i] for i in range(start, end)]
        tilts = [self._tilts[i] for i in range(start, end)]
        if first == 0:
            times.insert(0, -math.inf)
            tilts.insert(0, (0.0, 0.0))
        return np.array(times), np.array(tilts, dtype=float).reshape(-1, 2)


def predict_batch(pos_m: np.ndarray, vel_m_s: np.ndarray, t_from_s, t_to_s, issued_s: np.ndarray,
                  tilts_rad: np.ndarray, k_g, actuation_delay_s, accel_offset_m_s2):
    """States (pos, vel) (b, 2) [m, m/s] of a batch of plates propagated from t_from_s to
    t_to_s (b,) over the commands issued at issued_s (n,) [s, increasing], tilts_rad (b, n, 2):
    the tilt in force at t is the command issued at or before t - actuation_delay_s (b,), the
    first command from t_from_s on, the last up to t_to_s; each segment under the constant
    acceleration a = -k_g u + d (k_g (b,), d = accel_offset_m_s2 (b, 2)). A plate whose t_to_s
    is not after its t_from_s keeps its state."""
    p, v = np.array(pos_m, dtype=float), np.array(vel_m_s, dtype=float)
    n = len(issued_s)
    for j in range(n):
        t0 = np.maximum(issued_s[j] + actuation_delay_s, t_from_s) if j else t_from_s
        t1 = t_to_s if j == n - 1 else np.minimum(issued_s[j + 1] + actuation_delay_s, t_to_s)
        h = np.clip(t1 - t0, 0.0, None)[:, None]
        a = -np.asarray(k_g)[:, None] * tilts_rad[:, j] + accel_offset_m_s2
        p += v * h + 0.5 * a * h * h
        v += a * h
    return p, v


def predict(pos_m: np.ndarray, vel_m_s: np.ndarray, t_from_s: float, t_to_s: float,
            history: TiltHistory, k_g: float, actuation_delay_s: float = 0.0, accel_offset_m_s2=None):
    """State (pos, vel) [m, m/s], shape (2,), propagated from t_from_s to t_to_s (predict_batch
    over the commands of `history` that act in between; the tilt is 0 before the first).
    Returns new arrays; when t_to_s <= t_from_s the state is returned unchanged."""
    p = np.array(pos_m, dtype=float)
    v = np.array(vel_m_s, dtype=float)
    if not t_to_s > t_from_s:
        return p, v
    issued, tilts = history.acting(t_from_s - actuation_delay_s, t_to_s - actuation_delay_s)
    offset = np.zeros(2) if accel_offset_m_s2 is None else np.asarray(accel_offset_m_s2, dtype=float)
    p, v = predict_batch(p[None], v[None], np.array([t_from_s]), np.array([t_to_s]), issued, tilts[None],
                         np.array([k_g]), np.array([actuation_delay_s]), offset[None])
    return p[0], v[0]


class _DelayAlignment:
    """What the delay estimators share: the estimate and how an alignment is taken in.

    The start value is a guess, not evidence: the first alignment replaces it outright, later
    ones are blended in (`blend`). Nothing changes while the commands barely move (std below
    `min_excitation_rad`): a still plate says nothing about delay. One estimate per plate of
    `batch_shape` (() a single plate: `estimate_s` a float, `converged` a bool).
    """

    def __init__(self, initial_s: float, blend: float, min_excitation_rad: float, batch_shape: Tuple[int, ...] = ()):
        self.estimate_s = np.full(batch_shape, float(initial_s))[()]
        self.converged = np.zeros(batch_shape, bool)[()]   # True once a first alignment has been taken in
        self.blend, self.min_excitation = blend, min_excitation_rad

    @staticmethod
    def _best(costs) -> np.ndarray:
        """Index of the least cost along the last axis, refined by a parabola through its neighbours."""
        costs = np.asarray(costs, dtype=float)
        last = costs.shape[-1] - 1
        best = np.argmin(costs, axis=-1)

        def cost_at(index):
            return np.take_along_axis(costs, np.clip(index, 0, last)[..., None], -1)[..., 0]

        c0, c1, c2 = cost_at(best - 1), cost_at(best), cost_at(best + 1)
        denom = c0 - 2 * c1 + c2
        inner = (best > 0) & (best < last) & (denom > 0)
        frac = np.where(inner, 0.5 * (c0 - c2) / np.where(inner, denom, 1.0), 0.0)
        return best + frac

    def _take(self, measured_s, taken=True) -> None:
        """Take the alignment `measured_s` in where `taken` (per plate)."""
        weight = np.where(self.converged, self.blend, 1.0)
        self.estimate_s = np.where(taken, self.estimate_s + weight * (measured_s - self.estimate_s),
                                   self.estimate_s)[()]
        self.converged = (self.converged | taken)[()]


class DelayEstimator(_DelayAlignment):
    """Online estimate of the command -> plate delay from the commanded tilts and the tilts
    measured from /joint_states (FK), by least-squares alignment over a sliding window.

    Every `update_every` samples, for each candidate delay d on a grid (0..max_delay_s),
    cost(d) = mean |tilt_measured(t) - u_cmd(t - d)|^2 over the last `window_s`; the argmin
    is blended into the estimate (`blend`). Nothing changes while the commands barely move
    (std below `min_excitation_rad`).

    Estimating begins as soon as `min_window_s` of commands (plus the longest lag) are stored,
    over the window filled so far, and the first alignment replaces the start value outright:
    waiting for the full window and blending from the start value leaves a 0.2 s delay
    estimated at 0.03 s for 3.3 s and at 0.17 s after 4 s, and the MPC, planning for the
    wrong delay, drops the ball (docs/benchmarks/control.md, "Delay estimate start").

    `batch_shape` () estimates one plate's delay (the pipeline's); (batch,) a delay per plate
    of a batch stepped together (the training plant, ball_balance/policy/env.py), each plate
    exactly as if alone.
    """

    def __init__(self, initial_s: float, period_s: float, max_delay_s: float = 0.3, window_s: float = 3.0,
                 update_every: int = 25, blend: float = 0.5, min_excitation_rad: float = 0.003,
                 min_window_s: float = 0.6, batch_shape: Tuple[int, ...] = ()):
        super().__init__(initial_s, blend, min_excitation_rad, batch_shape)
        self.period_s = period_s
        self.max_lag = int(round(max_delay_s / period_s))
        self.capacity = int(round(window_s / period_s)) + self.max_lag + 1
        self.update_every = update_every
        self.min_window = max(2, int(round(min(min_window_s, window_s) / period_s)))
        # commanded and measured tilt pairs, a ring of `capacity` ticks per plate
        self._cmd = np.zeros((*batch_shape, self.capacity, 2))
        self._meas = np.zeros((*batch_shape, self.capacity, 2))
        self._length = 0                # ticks stored (at most capacity)
        self._count = 0                 # ticks added (the next one's ring slot: _count % capacity)

    def reset(self) -> None:
        self._length = 0

    def add(self, u_cmd, tilt_measured):
        """One control tick's commanded and measured tilt pairs (u_x, u_y) [rad] (shape batch_shape + (2,));
        returns the estimate [s]."""
        slot = self._count % self.capacity
        self._cmd[..., slot, :] = u_cmd
        self._meas[..., slot, :] = tilt_measured
        self._length = min(self._length + 1, self.capacity)
        self._count += 1
        if self._count % self.update_every == 0 and self._length - self.max_lag >= self.min_window:
            self._update()
        return self.estimate_s

    def _update(self) -> None:
        length = self._length
        order = np.arange(self._count - length, self._count) % self.capacity   # oldest first
        cmd, meas = self._cmd[..., order, :], self._meas[..., order, :]
        window = length - self.max_lag

        def per_plate(pairs):   # (..., ticks, 2) -> (..., 2 ticks): each plate's sums in one order
            return pairs.reshape(*pairs.shape[:-2], -1)

        # "not below" rather than ">=": commands gone NaN still count as moving
        excited = ~(per_plate(cmd[..., -window:, :]).std(axis=-1) < self.min_excitation)
        lagged = np.stack([cmd[..., length - window - lag:length - lag, :] for lag in range(self.max_lag + 1)],
                          axis=-3)                                   # (..., lags, window, 2)
        costs = np.mean(per_plate((meas[..., None, -window:, :] - lagged) ** 2), axis=-1)   # (..., lags)
        self._take(self._best(costs) * self.period_s, excited)


class StampedDelayEstimator(_DelayAlignment):
    """The command -> plate delay from tilts measured at irregular instants (camera frames:
    drops, stamp jitter, lost markers) against the command history, looked up by time.

    `add(t, tilt, command_history)` stores the measured tilt (u_x, u_y) [rad] at t [s];
    every `update_period_s` the samples of the last `window_s` are aligned with the command in
    force at t - d for each candidate d on a grid of `step_s` over 0..max_delay_s. The
    alignment is a correlation per axis (each signal less its window mean, divided by its
    spread): the measured tilt may be offset (a camera not level, a reference pose that is not
    the level plate) and scaled (a camera that does not look straight down, a plate that does
    not reach the full command), neither moves the best delay. The axes are weighted by the
    commands' variance; an axis whose commands barely move (`min_excitation_rad`) is left out,
    and with neither nothing changes. The best delay is taken in only when its correlation
    reaches `min_correlation` (a plate measured too noisily, or not following the commands,
    says nothing either). Alignment starts once `min_window_s` of samples are in.
    """

    def __init__(self, initial_s: float, max_delay_s: float = 0.3, window_s: float = 3.0, step_s: float = 0.005,
                 update_period_s: float = 0.25, blend: float = 0.2, min_excitation_rad: float = 0.003,
                 min_window_s: float = 1.0, min_correlation: float = 0.5):
        super().__init__(initial_s, blend, min_excitation_rad)
        self.delays_s = np.arange(0.0, max_delay_s + 0.5 * step_s, step_s)
        self.window_s, self.min_window_s = window_s, min(min_window_s, window_s)
        self.update_period_s = update_period_s
        self.min_correlation = min_correlation
        self.correlation = float("nan")   # of the last alignment's best delay
        self._t: Deque[float] = deque()
        self._meas: Deque[Tuple[float, float]] = deque()
        self._next_update_s = -np.inf

    def reset(self) -> None:
        """Forget the samples (the estimate stays)."""
        self._t.clear()
        self._meas.clear()
        self._next_update_s = -np.inf

    def add(self, t_s: float, tilt_measured, command_history: Callable[[], Tuple[np.ndarray, np.ndarray]]) -> float:
        """A measured tilt (u_x, u_y) [rad] at t_s; `command_history()` gives the commands (times
        [s], increasing, on the same clock, and (u_x, u_y) rows [rad]), called only when an
        alignment is due (building it costs more than the rest of a frame). Returns the estimate [s]."""
        if self._t and not t_s > self._t[-1]:
            if t_s < self._t[-1] - self.window_s:      # the clock went back: start again
                self.reset()
            else:
                return self.estimate_s                 # a repeated or out-of-order stamp
        self._t.append(float(t_s))
        self._meas.append((float(tilt_measured[0]), float(tilt_measured[1])))
        while self._t[0] < t_s - self.window_s:
            self._t.popleft()
            self._meas.popleft()
        if t_s >= self._next_update_s:
            times, values = command_history()
            self._update(np.asarray(times, dtype=float), np.asarray(values, dtype=float))
        return self.estimate_s

    def _update(self, cmd_t: np.ndarray, cmd_u: np.ndarray) -> None:
        t, meas = np.array(self._t), np.array(self._meas)
        if len(cmd_t) < 2:
            return
        # samples whose every candidate look-up falls inside the command history
        keep = t - self.delays_s[-1] >= cmd_t[0]
        if not keep.any() or t[-1] - t[keep][0] < self.min_window_s or keep.sum() < 10:
            return
        self._next_update_s = t[-1] + self.update_period_s
        t, meas = t[keep], meas[keep]
        idx = np.searchsorted(cmd_t, t[None, :] - self.delays_s[:, None], side="right") - 1
        u = cmd_u[idx]                                       # (delays, samples, 2)
        u = u - u.mean(axis=1, keepdims=True)
        m = meas - meas.mean(axis=0)
        spread = np.sqrt(np.mean(u ** 2, axis=1))             # (delays, 2)
        weights = np.where(spread[0] >= self.min_excitation, spread[0] ** 2, 0.0)
        m_spread = np.sqrt(np.mean(m ** 2, axis=0))
        if not weights.any() or not (m_spread[weights > 0.0] > 0.0).all():
            return
        corr = np.mean(u * m[None], axis=1) / np.maximum(spread * m_spread, 1e-12)
        score = corr @ weights / weights.sum()
        costs = 1.0 - score
        best = self._best(costs)
        self.correlation = float(score[int(np.argmin(costs))])
        if self.correlation < self.min_correlation:
            return
        step = self.delays_s[1] - self.delays_s[0] if len(self.delays_s) > 1 else 0.0
        self._take(best * step)
