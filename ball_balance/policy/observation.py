"""The policy's observation: one layout, built by the same code in training and at run time.

The plant is two decoupled axes (x'' = -k g sin(u) per axis), so the policy is one small
network shared by both axes; the model file still takes one flat vector (axis x's features,
then axis y's) and returns one action per axis, so a runtime needs no axis knowledge.

Per axis, newest first, everything in the plate frame and in SI units:

    error_m[HISTORY]      position error x - r of the (latency-predicted) state, this tick and before
    tilt_rad[HISTORY]     the tilts this law commanded on the previous ticks
    vel_error_m_s         v - v_ref of the (latency-predicted) state
    ff_tilt_rad           reference feed-forward -a_ref / (k g_nominal)
    pid_tilt_rad          what the PID alone would command this tick (the residual's base)
    age_s                 age of the ball state (capture -> this tick)
    gain_ratio            the plant estimate's k g over the k g the PID was tuned for (1 without
                          an estimate): how hard a tilt moves this ball, which the history shows
                          only slowly and an MPC-like correction scales with

The history lets the network see how the ball answered earlier tilts (the plant's gain and
the command-to-plate delay it lives with), which the PID cannot. The action per axis is a
correction in [-1, 1]; times `action_scale_rad` and `correction_weight` it is added to the PID
tilt.
"""
from __future__ import annotations

from typing import List, Tuple

import numpy as np

HISTORY = 16
AXES = ("x", "y")


def layout(history: int = HISTORY) -> List[Tuple[str, int, str]]:
    """(name, size, unit) of each field of one axis, in order."""
    return [("error_m", history, "m"), ("tilt_rad", history, "rad"), ("vel_error_m_s", 1, "m/s"),
            ("ff_tilt_rad", 1, "rad"), ("pid_tilt_rad", 1, "rad"), ("age_s", 1, "s"), ("gain_ratio", 1, "1")]


def axis_size(history: int = HISTORY) -> int:
    return sum(size for _, size, _ in layout(history))


def flat_names(history: int = HISTORY) -> List[str]:
    """One name per element of the flat observation vector (both axes)."""
    out = []
    for axis in AXES:
        for name, size, _ in layout(history):
            out += [f"{axis}.{name}"] if size == 1 else [f"{axis}.{name}[{k}]" for k in range(size)]
    return out


class ObservationBuilder:
    """Keeps the histories of `batch` independent plates and builds their observations.

    Arrays are (batch, 2): one row per plate, one column per axis. Run time uses batch 1.
    """

    def __init__(self, batch: int = 1, history: int = HISTORY):
        self.batch, self.history = batch, history
        self.errors = np.zeros((batch, 2, history))
        self.tilts = np.zeros((batch, 2, history))

    def reset(self, which=None) -> None:
        """Forget the history (all plates, or those where the boolean mask `which` is set)."""
        if which is None:
            self.errors[:] = 0.0
            self.tilts[:] = 0.0
        else:
            self.errors[which] = 0.0
            self.tilts[which] = 0.0

    def build(self, error_m, vel_error_m_s, ff_tilt_rad, pid_tilt_rad, age_s, gain_ratio=1.0) -> np.ndarray:
        """Push this tick's errors and return the raw observations, shape (batch, 2 * axis_size).
        age_s and gain_ratio are (batch,) or scalars; the others (batch, 2)."""
        self.errors[:, :, 1:] = self.errors[:, :, :-1]
        self.errors[:, :, 0] = error_m
        b = self.batch
        age = np.broadcast_to(np.asarray(age_s, dtype=float).reshape(-1, 1), (b, 2))
        ratio = np.broadcast_to(np.asarray(gain_ratio, dtype=float).reshape(-1, 1), (b, 2))
        per_axis = np.concatenate([self.errors, self.tilts, np.asarray(vel_error_m_s).reshape(b, 2, 1),
                                   np.asarray(ff_tilt_rad).reshape(b, 2, 1), np.asarray(pid_tilt_rad).reshape(b, 2, 1),
                                   age.reshape(b, 2, 1), ratio.reshape(b, 2, 1)], axis=2)
        return per_axis.reshape(b, -1)

    def record_tilt(self, tilt_rad) -> None:
        """The tilt pair commanded this tick (batch, 2): the newest entry of the next observation."""
        self.tilts[:, :, 1:] = self.tilts[:, :, :-1]
        self.tilts[:, :, 0] = tilt_rad


def correction_weight(error_m, fade_error_m: float, onset_error_m: float = 0.0, gain_ratio=1.0,
                      low_gain_onset: float = 0.0) -> np.ndarray:
    """The share of the policy's correction that applies, from the ball's distance to the
    reference (error_m (..., 2) [m], error_m[0] of both axes) and the plant estimate's gain
    ratio (scalar or (...,); observation's gain_ratio).

    fade_error_m: all of it within that distance, none beyond twice it, linear between (0: no
    fade). Far from the reference the ball is coming back from a push, where a teacher on the
    truth labels what the controller cannot see yet.
    onset_error_m: none within that distance, all of it beyond twice it (0: no onset). A model
    that only corrects the recovery from a push (the mpc_far teacher: no correction near the
    reference) leaves the PID alone where it is already good, with no imitation error there.
    low_gain_onset: with an onset, all of the correction also near the reference where the
    gain ratio is below low_gain_onset ** 2, none above low_gain_onset, linear in its log
    between (0: not at all). On a weak plant (low gravity) the PID, which only ever scales its
    feedback down, is slow, and the MPC's plan, which scales its tilt with the gain, is far
    better; a stronger plant or a long delay gives the MPC no such lead once the vision is
    noisy, so there the PID stays."""
    error_m = np.asarray(error_m, dtype=float)
    weight = np.ones(error_m.shape[:-1])
    if fade_error_m <= 0.0 and onset_error_m <= 0.0:
        return weight
    distance_m = np.hypot(error_m[..., 0], error_m[..., 1])
    if fade_error_m > 0.0:
        weight = weight * np.clip(2.0 - distance_m / fade_error_m, 0.0, 1.0)
    if onset_error_m > 0.0:
        onset = np.clip(distance_m / onset_error_m - 1.0, 0.0, 1.0)
        if low_gain_onset > 0.0:
            onset = np.maximum(onset, low_gain_share(gain_ratio, low_gain_onset))
        weight = weight * onset
    return weight


def low_gain_share(gain_ratio, low_gain_onset: float) -> np.ndarray:
    """0 for a gain ratio at or above low_gain_onset (< 1), 1 at or below its square, linear in
    log(gain_ratio) between: how far the plant is below the one the PID was tuned for."""
    log_ratio = np.log(np.maximum(np.asarray(gain_ratio, dtype=float), 1e-9))
    return np.clip(log_ratio / np.log(low_gain_onset) - 1.0, 0.0, 1.0)
