"""Joint commands ramped between control steps, for the controllers that write them.

A target that jumps once per control step (a staircase at 50-60 Hz) is taken by a stiff joint
servo within a few milliseconds: at every step the driven link's angular acceleration
spikes. On the ball-balancing plate, its surface under the ball (distance from the axis times
that acceleration) then drops faster than gravity, and after a large step the ball leaves the
plate (the project's docs/control.md, "The command ramp"). Spread over the period,
the same motion stays smooth, at the price of half a period of delay on average.

    q(t) = q_from + (q_to - q_from) min(1, (t - t_from) / T)

No ROS import; `at` writes into one array it owns (the real-time path allocates nothing).
"""
from __future__ import annotations

import math
from typing import Optional, Sequence

import numpy as np


class CommandRamp:
    """A straight line from the last command to the new target, reached after `duration_s`."""

    def __init__(self, n_joints: int):
        self._from = np.zeros(n_joints)
        self._delta = np.zeros(n_joints)
        self._out = np.zeros(n_joints)
        self._t_from_s = 0.0
        self._duration_s = 1.0
        self._target: Optional[Sequence[float]] = None

    @property
    def target(self) -> Optional[Sequence[float]]:
        """The target object the ramp leads to (None before the first): callers tell a new
        target from it by identity, as controllers hand targets over by reference."""
        return self._target

    def retarget(self, target: Sequence[float], written: Sequence[float], t_s: float, period_s: float,
                 duration_s: float) -> None:
        """A new target at the update at t_s: ramp on from `written`, the command last written
        (from the target itself while that holds a non-finite value: nothing written yet), as
        if started one update (period_s) before, so that this update already moves; reached
        after duration_s, at least one update."""
        self._target = target
        self.start(written if all(map(math.isfinite, written)) else target, target,
                   t_s - period_s, max(duration_s, period_s, 1e-6))

    def start(self, q_from: Sequence[float], q_to: Sequence[float], t_from_s: float, duration_s: float) -> None:
        """Ramp from q_from (the command at t_from_s) to q_to over duration_s (> 0)."""
        self._from[:] = q_from
        np.subtract(q_to, self._from, out=self._delta)
        self._t_from_s, self._duration_s = t_from_s, duration_s

    def at(self, t_s: float) -> np.ndarray:
        """The command at t_s: q_from before t_from_s, q_to from t_from_s + duration_s on."""
        fraction = min(1.0, max(0.0, (t_s - self._t_from_s) / self._duration_s))
        np.multiply(self._delta, fraction, out=self._out)
        self._out += self._from
        return self._out


class CommandIntervalEstimate:
    """How far apart new commands arrive (a controller that forwards another's commands does
    not know their rate): the first interval, then an exponential average of the intervals,
    each clamped to at most `ceiling_s` so that a pause moves it by one bounded step."""

    def __init__(self, ceiling_s: float, weight: float = 0.2):
        self.ceiling_s, self.weight = ceiling_s, weight
        self.interval_s = ceiling_s     # until two commands have come
        self._last_s = None
        self._measured = False

    def reset(self) -> None:
        """A new stream (activation): forget the last arrival, keep the estimate."""
        self._last_s = None

    def arrived(self, t_s: float) -> float:
        """A new command at t_s: the updated estimate [s]."""
        if self._last_s is not None:
            interval_s = min(self.ceiling_s, max(0.0, t_s - self._last_s))
            if self._measured:
                self.interval_s += self.weight * (interval_s - self.interval_s)
            else:
                self.interval_s, self._measured = interval_s, True
        self._last_s = t_s
        return self.interval_s
