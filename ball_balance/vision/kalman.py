"""Kalman filter of the ball in the plate frame (filterpy), constant velocity plus an optional
known acceleration from the commanded plate tilt.

State x = [x, y, vx, vy] (m, m/s), with `estimate_input_gain` also s, the ratio of the
acceleration the ball really shows to the known one; measurement z = [x, y] (m). Per frame,
with the time step dt from the frame stamps and the known acceleration a = (a_x, a_y):

    x' = x + vx dt + s a_x dt^2/2,   vx' = vx + s a_x dt,   s' = s      (likewise y)
    Q = q [[dt^4/4 I, dt^3/2 I], [dt^3/2 I, dt^2 I]],  q = sigma_a^2      white-noise acceleration
    H = [I 0],  R = sigma_z^2 I

The known acceleration is -k g sin(u) of the commanded tilt (the tracker's `known_acceleration`).
With it the model explains most of the ball's motion, so its process noise
`cmd_accel_noise_m_s2` is much smaller than `accel_noise_m_s2`, used without it (no recent
command): the filter then averages the detections over many frames instead of following them.
s is linear in the state because a is known, so the filter stays linear; it absorbs a wrong
k g (a solid ball rolls at 5/7 g where a shell rolls at 3/5, gravity or a plate gain differ),
which would otherwise show up as an acceleration error far above `cmd_accel_noise_m_s2`.
It drifts as a random walk (`input_gain_rate_per_s`) and stays within `input_gain_bounds`.

Measurement noise: with `adaptive_meas_noise` sigma_z is estimated online from the detections
themselves (`DetectionNoiseEstimator`: their scatter about the path through their neighbours),
independent of the filter's own tuning, and kept within [meas_noise_m, meas_noise_max_m]; a
camera, lighting or ball that detects worse than assumed then gets a filter that averages more
instead of passing the noise on to the controller.

Tilt lever: in plate coordinates a ball rolling on a tilting plate obeys
x'' = -k g sin(u) + c u'' with c = r + k d (r the ball radius, d the depth of the tilt axis
below the plate's surface; the ball's centre is r + d above the axis and its spin follows the
plate), so x = xi + c u with xi'' = -k g sin(u). With `lever` (c u of the commanded tilt, from
PlateCommandInput.lever_offset) the filter tracks xi, the detections less c u, and reports
xi + c u: c u is up to 3 mm at 0.15 rad, and without it the rolling model took c u' (about
20 mm/s while braking a push) for a velocity error.

A push: a detection beyond `maneuver_sigma` re-predicts its frame with `accel_noise_m_s2`.
With the small process noise the filter still takes a push up over several frames (in the
benchmark 111 mm/s short of a 0.15 m/s push one frame after it, 36 two frames after, against
69 and 8 for a constant-velocity filter with 1 m/s^2), and that lag, not the filter's accuracy
later, slowed the controllers' recovery. So `fast`, a plain constant-velocity filter with
`accel_noise_m_s2` and the same measurement noise, runs alongside, and for `maneuver_hold_s`
after such a detection its velocity is the one reported, unless the model had disagreed with
the detections before it (MODEL_AGREED_NIS: a long delay or a wrong gain, not a push). The
position stays the model's; during the hold it predicts with at least
`maneuver_accel_noise_m_s2` of process noise, so that position follows the pushed ball within
frames (with only the small noise it lagged the returning ball by 3-5 mm for most of the hold).
Its velocity is not reported then: its error after a push is a slow bias that the controllers
follow, where the constant-velocity filter's is noise that they average. With
`maneuver_confirm_frames` N > 1 a push needs a detection beyond `maneuver_sigma` followed by
N - 1 whose innovations point the same way and lie beyond `maneuver_confirm_sigma` (or one
beyond `gate_sigma`): a push keeps pushing the detections the same way, noise scatters them.
Only while the measurement noise is at least `maneuver_confirm_noise_m`: with less, a push
moves the ball beyond the noise within a frame and one detection tells, so waiting for a
second only brakes it a frame later. With the disturbance state a large change of d looks
like a push in its first frames. So from a push's detection on, a reference filter runs with
the model's own process noise, and the detections it sees are explained both ways, as a jump
of the ball's velocity and as a jump of d, each at the onset that fits it best (_JumpTest).
As soon as one explanation is better by the change test's bound, it stands: a change of d
ends the hold and the reference filter, corrected by the change, takes over.

Delay: the plate reaches a command some time after the tracker receives it (the arm's latency
and servo lag, 0.03-0.2 s in the benchmark's latency domains); the known acceleration and the
lever use the command in force `delay_s` before the frame. With `estimate_plate_cmd_delay`
`CommandDelayFromTilt` measures it: the plate's tilt from its marker pose each frame, aligned
with the command history over candidate delays (control/prediction.py StampedDelayEstimator).

A detection whose Mahalanobis distance sqrt(y^T S^-1 y) exceeds `gate_sigma` is ignored
(an outlier). Without a usable detection the filter coasts (predicts) for up to
`max_coast_frames` frames, still valid; then the track is dropped and the next detection
starts a new one. A gap longer than `max_dt_s` also drops the track. The noise and gain
estimates describe the camera and the plant, not the track: they survive a dropped track.
"""
from __future__ import annotations

import copy
import dataclasses
import math
from collections import deque
from dataclasses import dataclass
from typing import Deque, Optional, Tuple

import numpy as np
from filterpy.kalman import KalmanFilter

from ball_balance.control.prediction import StampedDelayEstimator
from ball_balance.rotations import matrix_to_rotvec
from ball_balance.vision.config import TRACKER_SCHEMA

CHI2_1_MEDIAN = 0.45493642311957283   # median of a chi-square variable with one degree of freedom
# the running innovation consistency (1 when the model is right) at most this: the model agreed
# with the detections. Only then is a detection beyond maneuver_sigma a push, or a bias of the
# innovations a change of d: a model that has disagreed for a while (a delay or a gain still
# being learned) is seeing its own error; the constant-velocity filter's velocity cost 1 mm in
# extreme_dr when it took over there too, and d taken for such an error shook the ball
MODEL_AGREED_NIS = 1.0
# the running consistency starts at 1 with a track; after this many of its time constants its
# start weighs 5 % and it describes the detections
CONSISTENCY_SETTLE_TIME_CONSTANTS = 3.0
_TRACKER_DEFAULTS = {p.name: p.default for p in TRACKER_SCHEMA}   # KalmanConfig's defaults
DISTURBANCE_STD_M_S2 = 0.3   # 1-sigma of a change of d: a force up to about 3 degrees of tilt
# A change of d (a force that starts, turns or ends) shows as innovations that keep one sign:
# their whitened sum over DISTURBANCE_CHANGE_WINDOW_S, squared and over its frames, is
# chi-square with 2 degrees of freedom while the model holds; beyond DISTURBANCE_CHANGE_CHI2
# (a 0.1 % false alarm per test) d has changed by an unknown amount (1-sigma
# DISTURBANCE_STD_M_S2) about half a window ago, and the filter's covariance says so. d starts
# at 0, known: a plate off level from the start is found as such a change, once the gain is
# learned, instead of being learned together with a gain that is still wrong
DISTURBANCE_CHANGE_WINDOW_S = 0.3
DISTURBANCE_CHANGE_CHI2 = 13.815510557964274


def add_white_acceleration(M: np.ndarray, q, dt) -> None:
    """M[..., :4, :4] += q [[dt^4/4 I, dt^3/2 I], [dt^3/2 I, dt^2 I]]: a white-noise acceleration
    of density q over dt, on the states [x, y, vx, vy]. q and dt are scalars, or one value per
    matrix of a batch M (b, n, n) (the training plant's filter)."""
    pp, pv, vv = q * (dt ** 4 / 4), q * (dt ** 3 / 2), q * dt ** 2
    M[..., 0, 0] += pp
    M[..., 1, 1] += pp
    M[..., 0, 2] += pv
    M[..., 2, 0] += pv
    M[..., 1, 3] += pv
    M[..., 3, 1] += pv
    M[..., 2, 2] += vv
    M[..., 3, 3] += vv


@dataclass
class ChangeFrame:
    """A detection in the change test's window: what the test and the change's estimate need."""
    t: float                     # stamp [s]
    whitened: np.ndarray         # the innovation whitened by its covariance
    nis: float                   # the running consistency before it
    innovation: np.ndarray       # z - H x of the prediction [m]
    S: np.ndarray                # its covariance
    transition: np.ndarray       # the product of the F's since the previous update
    K: Optional[np.ndarray] = None   # the update's gain, once made


def consistency_settle_s(time_constant_s: float) -> float:
    """How old a track must be before its running consistency (time constant
    `model_mismatch_time_constant_s`) describes the detections rather than its start value."""
    return CONSISTENCY_SETTLE_TIME_CONSTANTS * time_constant_s


def state_pair(n: int, first: int) -> np.ndarray:
    """The columns (n, 2) that pick the states first and first + 1 (an x and y pair)."""
    columns = np.zeros((n, 2))
    columns[first, 0] = columns[first + 1, 1] = 1.0
    return columns


def disturbance_rows(d_index: int) -> np.ndarray:
    """The state indices (x, vx, d_x) and (y, vy, d_y) of a filter whose d starts at d_index."""
    return np.array([[0, 2, d_index], [1, 3, d_index + 1]])


def disturbance_jerk(q_d, dt) -> np.ndarray:
    """The process noise (..., 3, 3) that a random walk of d with jerk density q_d adds over dt
    to (x, vx, d_x) (likewise y); q_d and dt scalars, or one value per filter of a batch."""
    q_d, dt = np.asarray(q_d, dtype=float)[..., None, None], np.asarray(dt, dtype=float)[..., None, None]
    return q_d * np.array([[1 / 20, 1 / 8, 1 / 6], [1 / 8, 1 / 3, 1 / 2], [1 / 6, 1 / 2, 1.0]]) \
        * dt ** np.array([[5, 4, 3], [4, 3, 2], [3, 2, 1]])


def open_disturbance(P: np.ndarray, T, d_index: int) -> None:
    """Widen the covariance P (n, n), or a batch of them (b, n, n) with T (b,), by that of a
    change of d of 1-sigma DISTURBANCE_STD_M_S2 that happened T ago, with the velocity and
    position it has moved since."""
    T = np.asarray(T, dtype=float)[..., None]
    J = np.concatenate([T * T / 2.0, T, np.ones_like(T)], axis=-1)        # (..., 3)
    rows = disturbance_rows(d_index)
    P[..., rows[:, :, None], rows[:, None, :]] += DISTURBANCE_STD_M_S2 ** 2 * (J[..., None, :, None]
                                                                              * J[..., None, None, :])


def estimate_change(frames, d_index: int) -> Optional[np.ndarray]:
    """The state correction for the change of d that a change test's window shows, or None.
    `frames` are the window's ChangeFrame in order, the current frame last (its innovation is
    not used; its transition takes the correction to its prediction). For each frame the
    change may have happened in the prediction into, a _Jump of d is fitted to the
    innovations since; the onset of the largest evidence under the change's prior
    N(0, DISTURBANCE_STD_M_S2^2 I) is taken (generalised likelihood ratio, Willsky and Jones),
    and the correction is that jump's posterior mean. The caller opens the covariance as for a
    change of unknown size (open_disturbance), so the frames that follow still move d."""
    columns = state_pair(frames[0].transition.shape[0], d_index)
    transitions = [frame.transition for frame in frames]
    seen = frames[:-1]
    jumps = [_Jump.since(i, seen, transitions, columns) for i in range(len(seen))]
    if not jumps:
        return None
    best = max(jumps, key=lambda jump: jump.evidence(DISTURBANCE_STD_M_S2))
    return best.posterior(DISTURBANCE_STD_M_S2)[0]


class _Jump:
    """One explanation of a push's detections for _JumpTest: a jump of the states that
    `columns` (n, 2) picks, in the prediction into a frame at onset_s, with the terms of its
    generalised likelihood ratio over the frames since (estimate_change, kept up frame by
    frame): B and A as there, the information and the score."""

    def __init__(self, onset_s: float, B: np.ndarray):
        self.onset_s, self.B = onset_s, B
        self.A = np.zeros_like(B)
        self.information = np.zeros((2, 2))
        self.score = np.zeros(2)
        self._signature = None

    @classmethod
    def since(cls, i: int, frames, transitions, columns: np.ndarray) -> _Jump:
        """The jump of `columns` in the prediction into frames[i], fitted to frames[i:] (each
        with its update's gain); transitions[j] is the prediction into frame j, one more than
        the frames: the last takes the jump to the frame after them."""
        jump = cls(frames[i].t, transitions[i] @ columns)
        for j in range(i, len(frames)):
            jump.add(frames[j].innovation, frames[j].S)
            jump.take_up(frames[j].K)
            jump.predict(transitions[j + 1])
        return jump

    def predict(self, F: np.ndarray) -> None:
        self.B, self.A = F @ self.B, F @ self.A

    def add(self, innovation: np.ndarray, S: np.ndarray) -> None:
        """A frame's innovation and its covariance, before the update."""
        G = (self.B - self.A)[:2]
        S_inv_G = np.linalg.solve(S, G)
        self.score += S_inv_G.T @ innovation
        self.information += G.T @ S_inv_G
        self._signature = G

    def take_up(self, K: np.ndarray) -> None:
        """The update's gain: how much of the jump the filter took up."""
        self.A = self.A + K @ self._signature

    def statistic(self) -> float:
        """Twice the log-likelihood gained by the jump of the best size: score^T I^-1 score."""
        if np.linalg.det(self.information) <= 0.0:
            return 0.0
        return float(self.score @ np.linalg.solve(self.information, self.score))

    def evidence(self, prior_std: float) -> float:
        """Log evidence of the jump against none under its prior N(0, prior_std^2 I), up to a
        constant."""
        information = self.information + np.eye(2) / prior_std ** 2
        return float(self.score @ np.linalg.solve(information, self.score)) \
            - math.log(np.linalg.det(information) * prior_std ** 4)

    def posterior(self, prior_std: float):
        """The jump's effect on the state now, given the frames since its onset and its prior
        N(0, prior_std^2 I): the mean and the covariance to add to the reference filter's."""
        covariance = np.linalg.inv(self.information + np.eye(2) / prior_std ** 2)
        effect = self.B - self.A
        return effect @ (covariance @ self.score), effect @ covariance @ effect.T


class _JumpTest:
    """After a push's detection (with the disturbance state and a known acceleration): was it a
    push, a jump of the ball's velocity, or a force that started or turned, a change of d? A
    reference filter runs on from before the detection with the model's own process noise, and
    for each onset from the change test's window on, each of the two jumps is fitted to its
    innovations (generalised likelihood ratio, as estimate_change). Both explanations have
    two free parameters and an onset, so their best fits compare directly: once twice the
    log-likelihood ratio between the best of each passes DISTURBANCE_CHANGE_CHI2 (the change
    test's bound) the test has decided."""

    def __init__(self, kf: KalmanFilter, window, transition: np.ndarray, t: float, d_index: int):
        self.reference = copy.deepcopy(kf)
        n = kf.x.shape[0]
        self.force_columns, self.push_columns = state_pair(n, d_index), state_pair(n, 2)   # d, (vx, vy)
        transitions = [frame.transition for frame in window] + [transition]
        self.forces = [_Jump.since(i, window, transitions, self.force_columns) for i in range(len(window))]
        self.pushes = [_Jump.since(i, window, transitions, self.push_columns) for i in range(len(window))]
        self._add_onset(t, transition)

    def _add_onset(self, t: float, transition: np.ndarray) -> None:
        """Both jumps in the prediction into the frame at t, whose transition that is."""
        self.forces.append(_Jump(t, transition @ self.force_columns))
        self.pushes.append(_Jump(t, transition @ self.push_columns))

    def predict(self, t: float) -> None:
        """After the reference filter's prediction into the frame at t: the jumps so far move
        on, and either may happen in this prediction too."""
        for jump in self.forces + self.pushes:
            jump.predict(self.reference.F)
        self._add_onset(t, self.reference.F)

    def update(self, z: np.ndarray) -> Optional[str]:
        """Fold in detection z: "force" or "push" once decided, else None."""
        kf = self.reference
        innovation = z - kf.H @ kf.x
        S = kf.H @ kf.P @ kf.H.T + kf.R
        jumps = self.forces + self.pushes
        for jump in jumps:
            jump.add(innovation, S)
        kf.update(z)
        for jump in jumps:
            jump.take_up(kf.K)
        force = max(jump.statistic() for jump in self.forces)
        push = max(jump.statistic() for jump in self.pushes)
        if force - push > DISTURBANCE_CHANGE_CHI2:
            return "force"
        if push - force > DISTURBANCE_CHANGE_CHI2:
            return "push"
        return None

    def best_force(self) -> _Jump:
        return max(self.forces, key=_Jump.statistic)


@dataclass(frozen=True)
class TrackEstimate:
    x: float
    y: float
    vx: float
    vy: float
    fresh: bool          # this frame's detection was used (ball_found)
    valid: bool          # a usable estimate (fresh or coasting)
    gated: bool = False  # a detection was rejected as an outlier


class DetectionNoiseEstimator:
    """Standard deviation of the detections (per axis, m) from consecutive detection triples.

    For detections z0, z1, z2 at t0 < t1 < t2, the middle one's distance from the straight line
    through its neighbours, r = z1 - (w0 z0 + w2 z2) with w0 = (t2 - t1) / (t2 - t0) and
    w2 = 1 - w0, has variance sigma^2 (1 + w0^2 + w2^2) for independent noise of std sigma; a
    constant acceleration a adds -a (t1 - t0)(t2 - t1) / 2, removed with the known acceleration
    when there is one. The estimate is the median of the normalised r^2 over the last `window`
    triples (both axes) divided by the chi-square median, so the frames around a push, a hand
    or an outlier barely move it. None until `min_samples` triples are in.
    """

    def __init__(self, window: int = 60, min_samples: int = 10, max_span_s: float = 0.25):
        self.max_span_s = max_span_s
        self.min_samples = min_samples
        self._last: Deque[Tuple[float, np.ndarray, np.ndarray]] = deque(maxlen=3)
        self._samples: Deque[float] = deque(maxlen=2 * window)

    def add(self, t: float, z: Tuple[float, float], accel: Optional[Tuple[float, float]] = None) -> None:
        """A detection z (m) at stamp t (s); accel (m/s^2) the known acceleration or None."""
        if self._last and not t > self._last[-1][0]:
            return                                    # repeated or out-of-order stamp
        a = np.zeros(2) if accel is None else np.asarray(accel, dtype=float)
        self._last.append((t, np.asarray(z, dtype=float), a))
        if len(self._last) < 3:
            return
        (t0, z0, _), (t1, z1, a1), (t2, z2, a2) = self._last
        if t2 - t0 > self.max_span_s:
            return                                    # a gap: the path between is not a line
        w0 = (t2 - t1) / (t2 - t0)
        w2 = 1.0 - w0
        a = 0.5 * (a1 + a2)                       # the known acceleration over the triple
        r = z1 - (w0 * z0 + w2 * z2) + 0.5 * a * (t1 - t0) * (t2 - t1)
        self._samples.extend((r ** 2 / (1.0 + w0 ** 2 + w2 ** 2)).tolist())

    def sigma_m(self) -> Optional[float]:
        """The estimated detection noise (1 sigma per axis, m), None before enough detections."""
        if len(self._samples) < 2 * self.min_samples:
            return None
        return float(np.sqrt(np.median(np.asarray(self._samples)) / CHI2_1_MEDIAN))


class PlateCommandInput:
    """The known acceleration from the commanded plate tilts: x'' = -k g sin(u), with u the
    command in force `delay_s` before the frame (the arm reaches a command that much later),
    None when no command arrived within `timeout_s` of the frame (no controller running).

    `lever_offset` gives the part of the ball's plate-frame position that the tilt itself
    causes: the ball's centre sits above the tilt axis and the ball rolls on the plate, so
    tilting the plate by u moves the centre by lever_m u in plate coordinates (BallKalman)."""

    def __init__(self, k_g_m_s2: float, delay_s: float = 0.0, timeout_s: float = 0.2, max_len: int = 512,
                 lever_m: float = 0.0):
        self.k_g = k_g_m_s2
        self.delay_s = delay_s
        self.timeout_s = timeout_s
        self.lever_m = lever_m
        self._commands: Deque[Tuple[float, float, float]] = deque(maxlen=max_len)   # (t, u_x, u_y)

    def add(self, u_x: float, u_y: float, t_s: float) -> None:
        """A command (rad) received at t_s; an older stamp than the last one replaces the history."""
        if self._commands and t_s < self._commands[-1][0]:
            self._commands.clear()
        self._commands.append((t_s, u_x, u_y))

    def recent(self, now_s: float) -> bool:
        """A command arrived within `timeout_s` of now_s (a controller is running)."""
        return bool(self._commands) and abs(now_s - self._commands[-1][0]) <= self.timeout_s

    def history(self) -> Tuple[np.ndarray, np.ndarray]:
        """The stored commands: receipt times (s, increasing) and (u_x, u_y) rows (rad)."""
        rows = np.array(self._commands, dtype=float).reshape(-1, 3)
        return rows[:, 0], rows[:, 1:]

    def tilt(self, now_s: float) -> Optional[Tuple[float, float]]:
        """(u_x, u_y) in rad in force `delay_s` before now_s, or None (no recent command)."""
        if not self.recent(now_s):
            return None
        at = now_s - self.delay_s
        u_x, u_y = self._commands[0][1:]
        for t_i, ux, uy in self._commands:
            if t_i > at:
                break
            u_x, u_y = ux, uy
        return u_x, u_y

    def acceleration(self, now_s: float) -> Optional[Tuple[float, float]]:
        """(a_x, a_y) in m/s^2 at now_s, or None."""
        return self.inputs(now_s)[0]

    def lever_offset(self, now_s: float) -> Optional[Tuple[float, float]]:
        """(lever_m u_x, lever_m u_y) in m at now_s, or None (no lever, no recent command)."""
        return self.inputs(now_s)[1]

    def inputs(self, now_s: float) -> Tuple[Optional[Tuple[float, float]], Optional[Tuple[float, float]]]:
        """(acceleration, lever offset) at now_s, as acceleration() and lever_offset(), from one
        look-up of the tilt in force (BallKalman.step takes both)."""
        u = self.tilt(now_s)
        if u is None:
            return None, None
        accel = (-self.k_g * float(np.sin(u[0])), -self.k_g * float(np.sin(u[1])))
        lever = (self.lever_m * float(u[0]), self.lever_m * float(u[1])) if self.lever_m != 0.0 else None
        return accel, lever


def plate_tilt_rad(R_ref: np.ndarray, R: np.ndarray) -> Tuple[float, float]:
    """(u_x, u_y) [rad] of the plate at rotation R relative to R_ref, both the plate's rotation
    in one fixed frame (camera or world), in the commands' convention (control/kinematics.py:
    the plate-frame rotation vector is (u_y, -u_x, 0)). R_ref^T R does not depend on that frame,
    so a camera that is not level or looks at the plate obliquely measures the same tilts."""
    w = matrix_to_rotvec(np.asarray(R_ref).T @ np.asarray(R))
    return float(-w[1]), float(w[0])


class CommandDelayFromTilt:
    """Sets `commands.delay_s` (PlateCommandInput) to the delay the plate's measured tilt shows.

    Each frame with a plate pose gives the tilt relative to a reference pose (the first one,
    taken again when the plate seems to have turned by more than `REANCHOR_RAD`, i.e. the
    camera moved); while commands arrive, a StampedDelayEstimator aligns those tilts with the
    command history. Its correlation per axis ignores the reference's offset and the scale; a
    still plate (commands that barely move) or a noisy or lost pose keeps the current value."""

    REANCHOR_RAD = 0.5

    def __init__(self, commands: PlateCommandInput, estimator: StampedDelayEstimator):
        self.commands = commands
        self.estimator = estimator
        self.commands.delay_s = estimator.estimate_s
        self._R_ref: Optional[np.ndarray] = None

    @classmethod
    def from_config(cls, cfg, commands: PlateCommandInput) -> CommandDelayFromTilt:
        """The estimate a TrackerConfig describes, starting from plate_cmd_delay_s."""
        return cls(commands, StampedDelayEstimator(cfg.plate_cmd_delay_s, cfg.plate_cmd_delay_max_s,
                                                   cfg.plate_cmd_delay_window_s))

    @property
    def delay_s(self) -> float:
        return self.estimator.estimate_s

    def add_rotation(self, t_s: float, R: np.ndarray) -> float:
        """The plate's rotation R (3x3, in a fixed frame) measured at t_s, on the commands'
        clock; returns the delay in use (s)."""
        if self._R_ref is None:
            self._R_ref = np.array(R, dtype=float)
        tilt = plate_tilt_rad(self._R_ref, R)
        if math.hypot(*tilt) > self.REANCHOR_RAD:
            self._R_ref = np.array(R, dtype=float)
            self.estimator.reset()
            return self.delay_s
        return self.add_tilt(t_s, tilt)

    def add_tilt(self, t_s: float, tilt: Tuple[float, float]) -> float:
        """A measured tilt (u_x, u_y) [rad, any constant offset] at t_s; returns the delay (s)."""
        if self.commands.recent(t_s):
            self.commands.delay_s = self.estimator.add(t_s, tilt, self.commands.history)
        return self.delay_s


@dataclass(frozen=True)
class KalmanConfig:
    """BallKalman's settings: the tracker parameters of the same names, whose schema
    (TRACKER_SCHEMA, ball_balance/vision/config.py) describes them and gives the defaults.
    `from_tracker` takes them from a TrackerConfig; `dataclasses.replace` changes some."""

    meas_noise_m: float = _TRACKER_DEFAULTS["meas_noise_m"]
    accel_noise_m_s2: float = _TRACKER_DEFAULTS["accel_noise_m_s2"]
    init_vel_std_m_s: float = _TRACKER_DEFAULTS["init_vel_std_m_s"]
    gate_sigma: float = _TRACKER_DEFAULTS["gate_sigma"]
    max_coast_frames: int = _TRACKER_DEFAULTS["max_coast_frames"]
    max_dt_s: float = _TRACKER_DEFAULTS["max_dt_s"]
    cmd_accel_noise_m_s2: float = _TRACKER_DEFAULTS["cmd_accel_noise_m_s2"]
    estimate_input_gain: bool = _TRACKER_DEFAULTS["estimate_input_gain"]
    input_gain_bounds: Tuple[float, float] = _TRACKER_DEFAULTS["input_gain_bounds"]
    input_gain_std: float = _TRACKER_DEFAULTS["input_gain_std"]
    input_gain_rate_per_s: float = _TRACKER_DEFAULTS["input_gain_rate_per_s"]
    model_mismatch_time_constant_s: float = _TRACKER_DEFAULTS["model_mismatch_time_constant_s"]
    maneuver_sigma: float = _TRACKER_DEFAULTS["maneuver_sigma"]
    maneuver_hold_s: float = _TRACKER_DEFAULTS["maneuver_hold_s"]
    maneuver_accel_noise_m_s2: float = _TRACKER_DEFAULTS["maneuver_accel_noise_m_s2"]
    maneuver_confirm_frames: int = _TRACKER_DEFAULTS["maneuver_confirm_frames"]
    maneuver_confirm_sigma: float = _TRACKER_DEFAULTS["maneuver_confirm_sigma"]
    maneuver_confirm_noise_m: float = _TRACKER_DEFAULTS["maneuver_confirm_noise_m"]
    adaptive_meas_noise: bool = _TRACKER_DEFAULTS["adaptive_meas_noise"]
    meas_noise_max_m: float = _TRACKER_DEFAULTS["meas_noise_max_m"]
    meas_noise_window_frames: int = _TRACKER_DEFAULTS["meas_noise_window_frames"]
    disturbance_time_constant_s: float = _TRACKER_DEFAULTS["disturbance_time_constant_s"]

    @classmethod
    def from_tracker(cls, cfg) -> KalmanConfig:
        """The filter settings of a TrackerConfig (ball_balance.vision.config)."""
        values = {f.name: getattr(cfg, f.name) for f in dataclasses.fields(cls)}
        return cls(**{**values, "input_gain_bounds": tuple(cfg.input_gain_bounds)})

    def constant_velocity(self) -> KalmanConfig:
        """These settings for a plain constant-velocity filter (BallKalman.fast): the same
        noises, gate and coasting, no adaptation, no push detection; without a known
        acceleration its process noise is accel_noise_m_s2 anyway."""
        return dataclasses.replace(self, cmd_accel_noise_m_s2=self.accel_noise_m_s2, estimate_input_gain=False,
                                   adaptive_meas_noise=False, model_mismatch_time_constant_s=0.0, maneuver_sigma=0.0,
                                   disturbance_time_constant_s=0.0)


class BallKalman:
    """Tracks one ball with the settings `cfg`; `step()` once per frame with the frame's stamp."""

    def __init__(self, cfg: KalmanConfig):
        self.cfg = cfg
        self.sigma_a = cfg.accel_noise_m_s2
        self.sigma_a_cmd = cfg.cmd_accel_noise_m_s2
        self.init_vel_std = cfg.init_vel_std_m_s
        self.gate_sigma = cfg.gate_sigma
        self.max_coast_frames = cfg.max_coast_frames
        self.max_dt_s = cfg.max_dt_s
        self.meas_noise_min_m = cfg.meas_noise_m
        self.meas_noise_max_m = max(cfg.meas_noise_max_m, cfg.meas_noise_m)
        self.noise = DetectionNoiseEstimator(cfg.meas_noise_window_frames) if cfg.adaptive_meas_noise else None
        self.gain_state = cfg.estimate_input_gain
        self.gain_bounds = cfg.input_gain_bounds
        self.gain_rate = cfg.input_gain_rate_per_s
        self.dim = 5 if cfg.estimate_input_gain else 4
        # the disturbance d = (d_x, d_y) [m/s^2], the last two states, a random walk whose jerk
        # density is the model's white acceleration over the time constant squared: d is then
        # the part of the acceleration error that persists longer than about that
        self.disturbance_state = cfg.disturbance_time_constant_s > 0.0
        self.q_d = (cfg.cmd_accel_noise_m_s2 / cfg.disturbance_time_constant_s) ** 2 if self.disturbance_state else 0.0
        if self.disturbance_state:
            self.d_index = self.dim
            self.dim += 2
            self._disturbance_rows = disturbance_rows(self.d_index)
        self._disturbance = (np.zeros(2), 0.0)   # kept over dropped tracks
        # (stamp, whitened innovation, running consistency before it), the last window
        self._innovations: Deque[ChangeFrame] = deque()
        self._track_start_s = 0.0
        self._window_start_s: Optional[float] = None
        self.disturbance_changes = 0  # changes of d found (total)
        # after a push's detection, until it decides: was it a push or a change of d?
        self._jump_test: Optional[_JumpTest] = None
        self._transition = np.eye(self.dim)   # F's product since the last update
        self.model_mismatch_time_constant_s = cfg.model_mismatch_time_constant_s
        self.nis = 1.0                # running mean of the normalised innovation squared (per axis)
        self.maneuver_sigma = cfg.maneuver_sigma
        self.maneuver_count = 0       # detections that re-predicted with accel_noise_m_s2 (total)
        self.maneuver_confirm_frames = cfg.maneuver_confirm_frames
        self.maneuver_confirm_sigma = cfg.maneuver_confirm_sigma
        self.maneuver_confirm_noise_m = cfg.maneuver_confirm_noise_m
        # detections in the current run that may be a push, the last one's innovation, and the
        # running innovation consistency before the run began (the first one raised it)
        self._excess = (0, np.zeros(2), 1.0)
        # after a push: the velocity of a plain constant-velocity filter run alongside
        self.maneuver_hold_s = cfg.maneuver_hold_s
        self._hold_until = -np.inf
        # ... during which the model's process noise is at least this
        self.sigma_a_maneuver = cfg.maneuver_accel_noise_m_s2
        self.fast: Optional[BallKalman] = None
        if cfg.maneuver_hold_s > 0.0 and cfg.maneuver_sigma > 0.0:
            self.fast = BallKalman(cfg.constant_velocity())
        self._last_prediction = (0.0, 0.0)   # (dt, q) of the last prediction
        kf = KalmanFilter(dim_x=self.dim, dim_z=2, dim_u=2)
        kf.H = np.eye(2, self.dim)                                           # z = H x
        kf.R = np.eye(2) * cfg.meas_noise_m ** 2                             # measurement noise
        self.kf = kf
        self._gain = (1.0, cfg.input_gain_std ** 2)   # s and its variance, kept over dropped tracks
        self.initialised = False
        self.coasted = 0              # frames predicted without a detection since the last one
        self.t_last: Optional[float] = None
        self.gated_count = 0          # detections rejected as outliers (total)
        self.reset_count = 0          # tracks dropped (total)

    @property
    def meas_noise_m(self) -> float:
        """The measurement noise (1 sigma per axis, m) in use."""
        return float(np.sqrt(self.kf.R[0, 0]))

    @property
    def disturbance_m_s2(self) -> Tuple[float, float]:
        """d: the ball's acceleration the known one does not explain [m/s^2] (0 without the state)."""
        if not self.disturbance_state:
            return 0.0, 0.0
        d = self.kf.x[self.d_index:self.d_index + 2] if self.initialised else self._disturbance[0]
        return float(d[0]), float(d[1])

    def level_offset_rad(self, k_g: float) -> Tuple[float, float]:
        """d as a plate-level offset per axis [rad]: the tilt u at which the ball stays still,
        s k_g sin(u) = d, for the known acceleration -k_g sin(u) (PlateCommandInput.k_g)."""
        scale = self.input_gain * k_g
        d = self.disturbance_m_s2
        return (math.asin(min(1.0, max(-1.0, d[0] / scale))), math.asin(min(1.0, max(-1.0, d[1] / scale))))

    @property
    def input_gain(self) -> float:
        """s: the acceleration the ball shows per unit of the known one (1 without the estimate)."""
        if not self.gain_state:
            return 1.0
        return float(self.kf.x[4]) if self.initialised else self._gain[0]

    def reset(self) -> None:
        """Drop the track: the next detection starts a new one."""
        if self.initialised:
            self.reset_count += 1
            if self.gain_state:
                self._gain = (float(self.kf.x[4]), float(self.kf.P[4, 4]))
            if self.disturbance_state:
                i = self.d_index
                self._disturbance = (np.array(self.kf.x[i:i + 2], dtype=float), float(self.kf.P[i, i]))
        self.initialised = False
        self.coasted = 0
        self.t_last = None
        self._excess = (0, np.zeros(2), 1.0)
        self._jump_test = None
        self._innovations.clear()
        self._window_start_s = None

    def _start(self, z: Tuple[float, float], t: float) -> None:
        kf = self.kf
        P = [kf.R[0, 0], kf.R[1, 1], self.init_vel_std ** 2, self.init_vel_std ** 2]
        x = [z[0], z[1], 0.0, 0.0]
        if self.gain_state:
            x.append(self._gain[0])
            P.append(self._gain[1])
        if self.disturbance_state:
            x += list(self._disturbance[0])
            P += [self._disturbance[1]] * 2
        kf.x = np.array(x)
        kf.P = np.diag(P)
        self.initialised, self.coasted, self.t_last = True, 0, t
        self._transition = np.eye(self.dim)
        self._track_start_s = t

    def _predict(self, dt: float, accel: Optional[Tuple[float, float]], holding: bool = False,
                 kf: Optional[KalmanFilter] = None) -> None:
        q = self.process_noise(accel is not None, holding)
        main = kf is None
        if main:
            kf = self.kf
            self._last_prediction = (dt, q)
        I2 = np.eye(2)
        F = np.eye(self.dim)
        F[0:2, 2:4] = dt * I2
        Q = np.zeros((self.dim, self.dim))
        add_white_acceleration(Q, q, dt)
        a = None if accel is None else np.asarray(accel, dtype=np.float64)
        if self.disturbance_state and a is not None:
            # x' = ... + d dt^2/2, v' = ... + d dt, d' = d + w; without a known acceleration the
            # ball's acceleration is all process noise and d keeps its value
            i = self.d_index
            F[0:2, i:i + 2] = dt ** 2 / 2 * I2
            F[2:4, i:i + 2] = dt * I2
            rows = self._disturbance_rows                # (x, vx, d_x) and (y, vy, d_y)
            Q[rows[:, :, None], rows[:, None, :]] += disturbance_jerk(self.q_d, dt)
        if self.gain_state:
            if a is not None:                        # x' = ... + s a dt^2/2, v' = ... + s a dt
                F[0:2, 4] = a * dt ** 2 / 2
                F[2:4, 4] = a * dt
            Q[4, 4] = self.gain_rate ** 2 * dt
        if main and self.disturbance_state:
            self._transition = F @ self._transition
        kf.F, kf.Q = F, Q
        if self.gain_state:
            kf.predict()
            kf.P[4, 4] = min(kf.P[4, 4], self._gain_var_max)
        elif a is None:
            kf.predict()
        else:
            kf.B = np.zeros((self.dim, 2))
            kf.B[0:2], kf.B[2:4] = dt ** 2 / 2 * I2, dt * I2
            kf.predict(u=a)

    def _widen_last_prediction(self) -> None:
        """Add the process noise the last prediction would have had without a known acceleration
        (a push or a hand on the ball: the model did not see it coming)."""
        dt, q = self._last_prediction
        extra = self.sigma_a ** 2 - q
        if extra <= 0.0 or dt <= 0.0:
            return
        add_white_acceleration(self.kf.P, extra, dt)
        self.maneuver_count += 1

    def process_noise(self, known_accel: bool, holding: bool = False) -> float:
        """q (m^2/s^4) for the next prediction: sigma_a^2 without a known acceleration; with one
        sigma_a_cmd^2, raised by the running innovation consistency (up to sigma_a^2) while the
        detections disagree with the model more than its covariance says (a wrong delay or gain).
        During a maneuver hold (`holding`) at least sigma_a_maneuver^2."""
        if not known_accel:
            q = self.sigma_a ** 2
        else:
            scale = 1.0
            if self.model_mismatch_time_constant_s > 0.0:
                scale = min(max(self.nis, 1.0), max(1.0, (self.sigma_a / self.sigma_a_cmd) ** 2))
            q = scale * self.sigma_a_cmd ** 2
        return max(q, self.sigma_a_maneuver ** 2) if holding else q

    @property
    def _gain_var_max(self) -> float:
        """s's variance never grows past a quarter of its range squared (no command for long)."""
        low, high = self.gain_bounds
        return ((high - low) / 4.0) ** 2

    def mahalanobis(self, z: Tuple[float, float]) -> float:
        """Distance of z from the predicted measurement, in standard deviations."""
        kf = self.kf
        y = np.asarray(z) - kf.H @ kf.x                    # innovation
        S = kf.H @ kf.P @ kf.H.T + kf.R                    # innovation covariance
        return float(np.sqrt(y @ np.linalg.solve(S, y)))

    def _adapt_noise(self, t: float, z: Tuple[float, float], accel) -> None:
        if accel is not None:
            accel = (self.input_gain * accel[0], self.input_gain * accel[1])
        self.noise.add(t, z, accel)
        sigma = self.noise.sigma_m()
        if sigma is not None:
            sigma = min(max(sigma, self.meas_noise_min_m), self.meas_noise_max_m)
            self.kf.R = np.eye(2) * sigma ** 2

    def step(self, t: float, z: Optional[Tuple[float, float]],
             accel: Optional[Tuple[float, float]] = None,
             lever: Optional[Tuple[float, float]] = None) -> TrackEstimate:
        """Advance to stamp t (s) and fold in detection z (m) if any; accel in m/s^2 or None.
        lever (m; PlateCommandInput.lever_offset): the part of the ball's plate-frame position
        the plate's tilt causes at t. The filter tracks the rest (the rolling the known
        acceleration explains) and adds it back to its position estimate."""
        if lever is None or z is None:
            estimate = self._step(t, z, accel)
        else:
            estimate = self._step(t, (z[0] - lever[0], z[1] - lever[1]), accel)
        if lever is not None:
            estimate = dataclasses.replace(estimate, x=estimate.x + lever[0], y=estimate.y + lever[1])
        if self.fast is not None:
            self.fast.kf.R = self.kf.R.copy()
            fast = self.fast.step(t, z)
            if estimate.valid and fast.valid and t <= self._hold_until:
                estimate = dataclasses.replace(estimate, vx=fast.vx, vy=fast.vy)
        return estimate

    def _step(self, t: float, z: Optional[Tuple[float, float]],
              accel: Optional[Tuple[float, float]] = None) -> TrackEstimate:
        if z is not None and self.noise is not None:
            self._adapt_noise(t, z, accel)
        dt_step = 0.0
        if self.initialised:
            dt = dt_step = t - self.t_last
            if dt > self.max_dt_s:
                self.reset()
            elif dt > 0.0:            # a repeated or out-of-order stamp only updates
                self._predict(dt, accel, holding=t <= self._hold_until)
                self.t_last = t
                if self._jump_test is not None:
                    if t > self._hold_until:     # undecided: the push stands
                        self._jump_test = None
                    else:
                        self._predict(dt, accel, kf=self._jump_test.reference)
                        self._jump_test.predict(t)
        if not self.initialised:
            if z is None:
                return self._estimate(fresh=False, valid=False)
            self._start(z, t)
            return self._estimate(fresh=True, valid=True)
        gated = False
        if z is not None:
            distance = self.mahalanobis(z)
            if self.maneuver_sigma > 0.0 and dt_step > 0.0 and self._push_seen(z, distance):
                nis = self._excess[2] if self._confirming() else self.nis
                if nis <= MODEL_AGREED_NIS:   # a model that agreed until the push began
                    self._hold_until = t + self.maneuver_hold_s
                    if self.disturbance_state and accel is not None and self._jump_test is None \
                            and self._settled(t):
                        self._jump_test = _JumpTest(self.kf, list(self._innovations), self._transition, t,
                                                    self.d_index)
                self._widen_last_prediction()
                distance = self.mahalanobis(z)
            if self.model_mismatch_time_constant_s > 0.0:   # a gated detection counts too, at the gate
                alpha = min(1.0, dt_step / self.model_mismatch_time_constant_s)
                self.nis += alpha * (min(distance, self.gate_sigma) ** 2 / 2.0 - self.nis)
            if distance <= self.gate_sigma:
                if self.disturbance_state:
                    self._find_disturbance_change(t, z, known=accel is not None, pushed=t <= self._hold_until)
                if self._jump_test is not None and self._decide_jump(t, z):
                    return self._estimate(fresh=True, valid=True)
                self.kf.update(np.asarray(z, dtype=np.float64))
                if self.disturbance_state:
                    if self._innovations and self._innovations[-1].K is None:
                        self._innovations[-1].K = self.kf.K.copy()
                    self._transition = np.eye(self.dim)
                self._clamp_gain(self.kf)
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

    def _find_disturbance_change(self, t: float, z: Tuple[float, float], known: bool, pushed: bool) -> None:
        """Before the update with detection z: test the innovations of the last
        DISTURBANCE_CHANGE_WINDOW_S for a change of d and, on one, correct the state by the
        change the window shows (estimate_change) and widen the covariance by that of a change
        of 1-sigma DISTURBANCE_STD_M_S2 that happened T ago (half the window): d by it, the
        velocity by it times T, the position by it times T^2/2, all correlated, so the
        innovations that follow still move d, and not the velocity, by what the change was.
        Without a known acceleration d is not in the model, and during a push's hold the
        innovations are the push's: the window starts again. The test assumes the model agreed
        with the detections before the window (MODEL_AGREED_NIS), measured over
        CONSISTENCY_SETTLE_TIME_CONSTANTS of the track; otherwise a bias is the model's error."""
        window = self._innovations
        if not known or pushed:
            window.clear()
            self._window_start_s = None
            return
        kf = self.kf
        innovation = np.asarray(z, dtype=np.float64) - kf.H @ kf.x
        S = kf.H @ kf.P @ kf.H.T + kf.R
        window.append(ChangeFrame(t, np.linalg.solve(np.linalg.cholesky(S), innovation), self.nis, innovation, S,
                                   self._transition))
        while t - window[0].t > DISTURBANCE_CHANGE_WINDOW_S:
            window.popleft()
        if self._window_start_s is None:
            self._window_start_s = t
        if t - self._window_start_s < DISTURBANCE_CHANGE_WINDOW_S:
            return
        window_start_s, nis_before = window[0].t, window[0].nis
        if nis_before > MODEL_AGREED_NIS or not self._settled(window_start_s):
            return                    # the model did not agree: a bias is its own error
        total = np.sum([frame.whitened for frame in window], axis=0)
        if float(total @ total) / len(window) <= DISTURBANCE_CHANGE_CHI2:
            return
        jump = estimate_change(list(window), self.d_index)
        if jump is not None:
            kf.x = kf.x + jump
        open_disturbance(kf.P, (t - window_start_s) / 2.0, self.d_index)
        self.disturbance_changes += 1
        window.clear()
        self._window_start_s = None

    def _clamp_gain(self, kf: KalmanFilter) -> None:
        """Keep kf's input gain s within input_gain_bounds (after an update)."""
        if self.gain_state:
            kf.x[4] = min(max(kf.x[4], self.gain_bounds[0]), self.gain_bounds[1])

    def _settled(self, t: float) -> bool:
        """Whether the running consistency at t describes the detections rather than its start
        value: the track is CONSISTENCY_SETTLE_TIME_CONSTANTS of its time constant old. Until
        then neither a change of d nor a force behind a push is looked for."""
        return t - self._track_start_s >= consistency_settle_s(self.model_mismatch_time_constant_s)

    def _decide_jump(self, t: float, z: Tuple[float, float]) -> bool:
        """Fold detection z into the jump test. When it finds a change of d, the reference
        filter, with the change's posterior (its mean and covariance given the frames since its
        onset, under the 0.3 m/s^2 prior) added, becomes the filter, the push's hold ends, and
        True is returned (z is in it). When it finds a push, the test ends and the hold goes on."""
        decision = self._jump_test.update(np.asarray(z, dtype=np.float64))
        if decision is None:
            return False
        test, self._jump_test = self._jump_test, None
        if decision == "push":
            return False
        kf = test.reference
        mean, covariance = test.best_force().posterior(DISTURBANCE_STD_M_S2)
        kf.x, kf.P = kf.x + mean, kf.P + covariance
        self._clamp_gain(kf)
        self.kf = kf
        self._hold_until = -np.inf
        self._innovations.clear()
        self._window_start_s = None
        self._transition = np.eye(self.dim)
        self.disturbance_changes += 1
        self.coasted = 0
        return True

    def _push_seen(self, z: Tuple[float, float], distance: float) -> bool:
        """Whether this detection shows a push: beyond maneuver_sigma (maneuver_confirm_frames 1,
        or a measurement noise below maneuver_confirm_noise_m); else the maneuver_confirm_frames-th
        of a run that began beyond maneuver_sigma and went on the same way beyond
        maneuver_confirm_sigma; or beyond the gate."""
        if not self._confirming():
            if self._excess[0]:   # a run in progress ends (the next one records its own start)
                self._excess = (0, self._excess[1], self._excess[2])
            return distance > self.maneuver_sigma
        innovation = np.asarray(z, dtype=np.float64) - np.ravel(self.kf.x)[:2]
        count, previous, nis_before = self._excess
        if count and float(innovation @ previous) > 0.0 and distance > self.maneuver_confirm_sigma:
            count += 1
        else:
            count, nis_before = (1 if distance > self.maneuver_sigma else 0), self.nis
        self._excess = (count, innovation, nis_before)
        return count >= self.maneuver_confirm_frames or distance > self.gate_sigma

    def _confirming(self) -> bool:
        """Whether a push needs maneuver_confirm_frames detections: only while the measurement
        noise is at least maneuver_confirm_noise_m. Below it a push shows in one detection; above
        it a frame's step of a push is within the noise, so one detection cannot tell them apart."""
        return self.maneuver_confirm_frames > 1 and self.meas_noise_m >= self.maneuver_confirm_noise_m

    def _estimate(self, fresh: bool, valid: bool, gated: bool = False) -> TrackEstimate:
        """The current state; an invalid estimate keeps the last position with zero velocity
        (all zeros before the first track)."""
        x = np.ravel(self.kf.x)
        if not valid:
            return TrackEstimate(float(x[0]), float(x[1]), 0.0, 0.0, fresh, False, gated)
        return TrackEstimate(float(x[0]), float(x[1]), float(x[2]), float(x[3]), fresh, valid, gated)
