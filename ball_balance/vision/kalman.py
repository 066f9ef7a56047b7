"""Kalman filter of the ball in the plate frame, constant velocity plus an optional known
acceleration from the commanded plate tilt. `BatchBallKalman` runs it for a batch of balls
in numpy; the tracker's `BallKalman` is a batch of one, the training plant (policy/env.py)
steps a batch of episodes.

State x = [x, y, vx, vy, s] (m, m/s), s the ratio of the acceleration the ball really shows
to the known one, estimated with `estimate_input_gain` and else held at 1; measurement
z = [x, y] (m). Per frame,
with the time step dt from the frame stamps and the known acceleration a = (a_x, a_y):

    x' = x + vx dt + s a_x dt^2/2,   vx' = vx + s a_x dt,   s' = s      (likewise y)
    Q = q [[dt^4/4 I, dt^3/2 I], [dt^3/2 I, dt^2 I]],  q = sigma_a^2      white-noise acceleration
    H = [I 0],  R = sigma_z^2 I,  update in Joseph form

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
xi + c u: c u is up to 3 mm at 0.15 rad, and without it the rolling model would take c u'
(about 20 mm/s while braking a push) for a velocity error.

A push: a detection beyond `maneuver_sigma` re-predicts its frame with `accel_noise_m_s2`.
With the small process noise the filter still takes a push up over several frames (one frame
after a 0.15 m/s push its velocity is about 0.1 m/s short, a constant-velocity filter's with
1 m/s^2 about 0.07), and that lag, not the filter's accuracy later, sets how fast a
controller recovers. So `fast`, a plain constant-velocity filter with
`accel_noise_m_s2` and the same measurement noise, runs alongside, and for `maneuver_hold_s`
after such a detection its velocity is the one reported, unless the model had disagreed with
the detections before it (MODEL_AGREED_NIS: a long delay or a wrong gain, not a push). The
position stays the model's; during the hold it predicts with `accel_noise_m_s2`, the process
noise of motion the known acceleration does not explain, so that position follows the pushed
ball within frames (with only the small noise it would lag the returning ball by millimetres
for most of the hold).
Its velocity is not reported then: its error after a push is a slow bias that the controllers
follow, where the constant-velocity filter's is noise that they average. While the
measurement noise is at least `maneuver_confirm_noise_m` a push needs a detection beyond
`maneuver_sigma` and the next one pointing the same way beyond `maneuver_confirm_sigma` (or one
beyond `gate_sigma`): a push keeps pushing the detections the same way, noise scatters them.
With less noise a push moves the ball beyond the noise within a frame and one detection
tells, so waiting for a second only brakes it a frame later. With the disturbance state a
large change of d looks like a push in its first frames. So from a push's detection on, a
reference filter runs with the model's own process noise, and the detections it sees are
explained both ways, as a jump of the ball's velocity and as a jump of d, each at the onset
that fits it best (vision/disturbance.py JumpTest). As soon as one explanation is better by
the change test's bound, it stands: a change of d ends the hold and the reference filter,
corrected by the change, takes over, and the change is reviewed as below. The other way
round, a push the noise kept from being confirmed shows to the change test as a change of d:
a change found with a detection beyond `maneuver_sigma` in its window, and a change the jump
test decided on, is reviewed by the same kind of reference filter, the filter without the
change, until `maneuver_hold_s` after it (ChangeReview), and if a push explains the frames
better the change is undone.

Delay: the plate reaches a command some time after the tracker receives it (the arm's latency
and servo lag, 0.03-0.2 s in the benchmark's latency domains); the known acceleration and the
lever use the command in force `delay_s` before the frame. With `estimate_plate_cmd_delay`
`CommandDelayFromTilt` measures it: the plate's tilt from its marker pose each frame, aligned
with the command history over candidate delays (control/prediction.py StampedDelayEstimator).

A detection whose Mahalanobis distance sqrt(y^T S^-1 y) exceeds `gate_sigma` is ignored
(an outlier), unless it comes during a push's hold and the constant-velocity filter takes
it: a push faster than the model's gate allows, whose position and velocity the model then
takes from that filter. Without a usable detection the filter coasts (predicts) for up to
`max_coast_frames` frames, still valid; then the track is dropped and the next detection
starts a new one. A gap longer than `max_dt_s` also drops the track. The noise and gain
estimates describe the camera and the plant, not the track: they survive a dropped track.
"""
from __future__ import annotations

import dataclasses
import math
from collections import deque
from dataclasses import dataclass
from typing import Deque, Dict, Optional, Tuple

import numpy as np

from ball_balance.control.prediction import StampedDelayEstimator
from ball_balance.rotations import matrix_to_rotvec
from ball_balance.vision.config import TRACKER_SCHEMA
from ball_balance.vision.disturbance import (
    MODEL_AGREED_NIS,
    ChangeReview,
    ChangeTest,
    JumpTest,
    consistency_settle_s,
    disturbance_jerk,
    disturbance_rows,
)

CHI2_1_MEDIAN = 0.45493642311957283   # median of a chi-square variable with one degree of freedom
_TRACKER_DEFAULTS = {p.name: p.default for p in TRACKER_SCHEMA}   # KalmanConfig's defaults


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


def process_noise(nis, known_accel: bool, holding, cfg: KalmanConfig) -> np.ndarray:
    """q [m^2/s^4] of the next prediction of each filter of a batch (one: arrays of shape (1,)),
    whose running innovation consistency is nis: sigma_a^2 (`accel_noise_m_s2`) without a known
    acceleration; with one sigma_a_cmd^2 (`cmd_accel_noise_m_s2`), raised by the consistency
    (up to sigma_a^2) while the detections disagree with the model more than its covariance
    says (a wrong delay or gain). During a push's hold (`holding`) sigma_a^2: the push is
    motion the known acceleration does not explain."""
    nis = np.asarray(nis, dtype=float)
    sigma_a, sigma_cmd = cfg.accel_noise_m_s2, cfg.cmd_accel_noise_m_s2
    if not known_accel:
        q = np.full(nis.shape, sigma_a ** 2)
    elif cfg.model_mismatch_time_constant_s > 0.0:
        q = np.minimum(np.maximum(nis, 1.0), max(1.0, (sigma_a / sigma_cmd) ** 2)) * sigma_cmd ** 2
    else:
        q = np.full(nis.shape, sigma_cmd ** 2)
    return np.where(holding, sigma_a ** 2, q)


def prediction(dt, q, accel, dim: int, gain_index: Optional[int] = None, gain_rate_per_s: float = 0.0,
               d_index: Optional[int] = None, q_d: float = 0.0) -> Tuple[np.ndarray, np.ndarray]:
    """The transition F and the process noise Q (b, dim, dim) of the predictions over dt (b,)
    with white accelerations q (b,), of a batch of filters (one: arrays of shape (1,)); accel
    (b, 2) the known accelerations or None. With `gain_index`, the state there is s, the gain
    on the known acceleration (x' = x + v dt + s a dt^2/2, v' = v + s a dt), a random walk
    of `gain_rate_per_s`; with `d_index`, d = (d_x, d_y) from there on, an acceleration the
    known one does not explain (x' = ... + d dt^2/2, v' = ... + d dt), a random walk of jerk
    density q_d. Without a known acceleration the ball's acceleration is all process noise,
    and d keeps its value."""
    dt = np.asarray(dt, dtype=float)
    F = np.broadcast_to(np.eye(dim), (len(dt), dim, dim)).copy()
    F[:, 0, 2] = F[:, 1, 3] = dt
    Q = np.zeros((len(dt), dim, dim))
    add_white_acceleration(Q, q, dt)
    if accel is not None:
        if gain_index is not None:
            F[:, 0:2, gain_index] = accel * (dt ** 2 / 2)[:, None]
            F[:, 2:4, gain_index] = accel * dt[:, None]
        if d_index is not None:
            F[:, 0, d_index] = F[:, 1, d_index + 1] = dt ** 2 / 2
            F[:, 2, d_index] = F[:, 3, d_index + 1] = dt
            rows = disturbance_rows(d_index)                # (x, vx, d_x) and (y, vy, d_y)
            Q[:, rows[:, :, None], rows[:, None, :]] += disturbance_jerk(q_d, dt)[:, None]
    if gain_index is not None:
        Q[:, gain_index, gain_index] = gain_rate_per_s ** 2 * dt
    return F, Q



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
    """Standard deviation of the detections (per axis, m) from consecutive detection triples,
    for one ball or, with `batch`, for each ball of a batch (the training plant's filter).

    For detections z0, z1, z2 at t0 < t1 < t2, the middle one's distance from the straight line
    through its neighbours, r = z1 - (w0 z0 + w2 z2) with w0 = (t2 - t1) / (t2 - t0) and
    w2 = 1 - w0, has variance sigma^2 (1 + w0^2 + w2^2) for independent noise of std sigma; a
    constant acceleration a adds -a (t1 - t0)(t2 - t1) / 2, removed with the known acceleration
    when there is one. The estimate is the median of the normalised r^2 over the last `window`
    triples (both axes) divided by the chi-square median, so the frames around a push, a hand
    or an outlier barely move it. None (nan in a batch) until `min_samples` triples are in.
    """

    def __init__(self, window: int = 60, min_samples: int = 10, max_span_s: float = 0.25, batch: int = 1):
        self.b, self.max_span_s, self.min_samples = batch, max_span_s, min_samples
        self.t = np.full((batch, 3), np.nan)     # the last three detections, oldest first
        self.z = np.zeros((batch, 3, 2))
        self.a = np.zeros((batch, 3, 2))
        self.n_last = np.zeros(batch, int)
        self.samples = np.full((batch, 2 * window), np.inf)   # a ring; empty slots sort last
        self.n_samples = np.zeros(batch, int)
        self.ring_at = np.zeros(batch, int)

    def add(self, t: float, z, accel=None, det=None) -> None:
        """Detections z (b, 2) [m] at stamp t [s] of the balls `det` (b,) (all by default);
        accel (b, 2) [m/s^2] the known accelerations or None. For one ball, z and accel (2,).
        A repeated or out-of-order stamp is ignored."""
        z = np.asarray(z, dtype=float).reshape(self.b, 2)
        a = np.zeros((self.b, 2)) if accel is None else np.asarray(accel, dtype=float).reshape(self.b, 2)
        det = np.ones(self.b, bool) if det is None else det
        newer = det & ((self.n_last == 0) | (t > self.t[:, 2]))
        if not newer.any():
            return
        for last, value in ((self.t, t), (self.z, z[newer]), (self.a, a[newer])):
            last[newer, :2] = last[newer, 1:]
            last[newer, 2] = value
        self.n_last = np.where(newer, np.minimum(self.n_last + 1, 3), self.n_last)
        t0, t1, t2 = self.t[:, 0], self.t[:, 1], self.t[:, 2]
        use = newer & (self.n_last >= 3)
        use &= np.where(use, t2 - t0, np.inf) <= self.max_span_s   # a gap: the path between is no line
        if not use.any():
            return
        i = np.flatnonzero(use)
        w0 = ((t2 - t1) / (t2 - t0))[i]
        w2 = 1.0 - w0
        a = 0.5 * (self.a[i, 1] + self.a[i, 2])               # the known acceleration over the triple
        r = self.z[i, 1] - (w0[:, None] * self.z[i, 0] + w2[:, None] * self.z[i, 2]) \
            + 0.5 * a * ((t1 - t0) * (t2 - t1))[i, None]
        normalised = r ** 2 / (1.0 + w0 ** 2 + w2 ** 2)[:, None]
        ring = self.samples.shape[1]
        at = self.ring_at[i]
        self.samples[i, at % ring], self.samples[i, (at + 1) % ring] = normalised[:, 0], normalised[:, 1]
        self.ring_at[i] = at + 2
        self.n_samples[i] = np.minimum(self.n_samples[i] + 2, ring)

    def sigma(self, balls=None) -> np.ndarray:
        """The estimated detection noise per ball (b,) [m, 1 sigma per axis], nan before enough
        detections and for the balls not in the mask `balls` (all by default)."""
        out = np.full(self.b, np.nan)
        ready = self.n_samples >= 2 * self.min_samples
        if balls is not None:
            ready &= balls
        if ready.any():
            i = np.flatnonzero(ready)
            ordered = np.sort(self.samples[i], axis=1)
            n, rows = self.n_samples[i], np.arange(len(i))
            median = 0.5 * (ordered[rows, (n - 1) // 2] + ordered[rows, n // 2])   # n is even
            out[i] = np.sqrt(median / CHI2_1_MEDIAN)
        return out

    def sigma_m(self) -> Optional[float]:
        """One ball's estimated detection noise [m], None before enough detections."""
        sigma = float(self.sigma()[0])
        return None if math.isnan(sigma) else sigma


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
        """These settings for a plain constant-velocity filter (BatchBallKalman.fast): the same
        noises, gate and coasting, no adaptation, no push detection; without a known
        acceleration its process noise is accel_noise_m_s2 anyway."""
        return dataclasses.replace(self, cmd_accel_noise_m_s2=self.accel_noise_m_s2, estimate_input_gain=False,
                                   adaptive_meas_noise=False, model_mismatch_time_constant_s=0.0, maneuver_sigma=0.0,
                                   disturbance_time_constant_s=0.0)


GAIN_INDEX = 4    # the state's index of s, the input gain (held at 1 without its estimate)
D_INDEX = 5       # ... of d_x (d_y next), with the disturbance state


def innovation_covariance(P: np.ndarray, r) -> np.ndarray:
    """S = H P H^T + r I (..., 2, 2) of filters with covariances P (..., n, n) and measurement
    variances r (one per filter, or a scalar for one), H = [I 0]."""
    return P[..., :2, :2] + np.asarray(r)[..., None, None] * np.eye(2)


def innovation_inverse(P: np.ndarray, r: np.ndarray, y: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """S^-1 (b, 2, 2) of the innovations y (b, 2) of a batch of filters with covariances
    P (b, n, n) and measurement variances r (b,) (S = H P H^T + r I, H = [I 0]), and their
    Mahalanobis distances sqrt(y^T S^-1 y) (b,)."""
    s00, s01, s11 = P[:, 0, 0] + r, P[:, 0, 1], P[:, 1, 1] + r
    det_s = s00 * s11 - s01 * s01
    inv = np.empty((len(P), 2, 2))
    inv[:, 0, 0], inv[:, 1, 1] = s11 / det_s, s00 / det_s
    inv[:, 0, 1] = inv[:, 1, 0] = -s01 / det_s
    return inv, np.sqrt(np.maximum(np.einsum("bi,bij,bj->b", y, inv, y), 0.0))


def kalman_update(x: np.ndarray, P: np.ndarray, r: np.ndarray, y: np.ndarray, S_inv: np.ndarray):
    """The update of a batch of filters (x (b, n), P (b, n, n), r (b,)) with the innovations
    y (b, 2) and S^-1 (b, 2, 2): K = P H^T S^-1, x + K y and P in Joseph form,
    (I - K H) P (I - K H)^T + r K K^T, which stays symmetric and positive. Returns
    (x, P, K)."""
    K = np.einsum("bij,bjk->bik", P[:, :, :2], S_inv)
    x_new = x + np.einsum("bij,bj->bi", K, y)
    n = x.shape[1]
    IKH = np.broadcast_to(np.eye(n), (len(x), n, n)).copy()
    IKH[:, :, :2] -= K
    P_new = IKH @ P @ IKH.transpose(0, 2, 1) + r[:, None, None] * (K @ K.transpose(0, 2, 1))
    return x_new, P_new, K


class BatchBallKalman:
    """The tracker's filter for a batch of balls, numpy, all at once: the tracker's BallKalman
    is a batch of one, the training plant (policy/env.py) steps a batch of episodes with it.

    Per ball: state [x, y, vx, vy, s] (s held at 1 with zero variance without
    `estimate_input_gain`, which is then the plain known-acceleration model), with the
    disturbance state also [d_x, d_y]; the module's prediction and process noise; the
    measurement noise estimated from the detections' scatter (DetectionNoiseEstimator, over
    the batch), or fixed per ball (`fixed_meas_noise_m`, as the benchmark's fast mode sets it);
    the gate, coasting, track restarts (the noise, gain and d estimates survive them); pushes
    (maneuver_*), their constant-velocity filter `fast`, the change test of d and, after a
    push's detection, the jump test (vision/disturbance.py)."""

    def __init__(self, batch: int, cfg: KalmanConfig, fixed_meas_noise_m=None):
        self.b, self.cfg = batch, cfg
        self.sigma_a = cfg.accel_noise_m_s2
        self.gain_state = bool(cfg.estimate_input_gain)
        self.disturbance_state = cfg.disturbance_time_constant_s > 0.0
        self.dim = D_INDEX + 2 if self.disturbance_state else D_INDEX
        self.noise_min = cfg.meas_noise_m
        self.noise_max = max(cfg.meas_noise_max_m, cfg.meas_noise_m)
        self.noise = DetectionNoiseEstimator(cfg.meas_noise_window_frames, batch=batch) \
            if cfg.adaptive_meas_noise else None
        low, high = cfg.input_gain_bounds
        self.gain_var_max = ((high - low) / 4.0) ** 2   # s's variance after long without a command
        # R per ball: the configured noise, or with a fixed noise the larger of it and the ball's
        r0 = np.full(batch, cfg.meas_noise_m) if fixed_meas_noise_m is None or self.noise is not None \
            else np.maximum(cfg.meas_noise_m, fixed_meas_noise_m)
        self.r = r0 ** 2
        # d: a random walk whose jerk density is the model's white acceleration over the time
        # constant squared, so d is the part of the acceleration error that persists longer
        self.q_d = (cfg.cmd_accel_noise_m_s2 / cfg.disturbance_time_constant_s) ** 2 if self.disturbance_state else 0.0
        self.change = ChangeTest(batch, self.dim, D_INDEX, consistency_settle_s(cfg.model_mismatch_time_constant_s))
        self.transition = np.broadcast_to(np.eye(self.dim), (batch, self.dim, self.dim)).copy()  # F's since the update
        self.track_start = np.zeros(batch)
        self.jump_tests: Dict[int, JumpTest] = {}   # after a push's detection: a push or a change of d?
        # the estimates kept over dropped tracks: s, d and their variances
        self.saved_gain = np.ones(batch)
        self.saved_gain_var = np.full(batch, cfg.input_gain_std ** 2 if self.gain_state else 0.0)
        self.saved_d = np.zeros((batch, 2))
        self.saved_d_var = np.zeros(batch)
        self.x = np.zeros((batch, self.dim))
        self.p = np.zeros((batch, self.dim, self.dim))
        self.init = np.zeros(batch, bool)
        self.t_last = np.zeros(batch)
        self.coasted = np.zeros(batch, int)    # frames without a usable detection since the last one
        self.nis = np.ones(batch)              # running mean of the normalised innovation squared (per axis)
        self.model_has_agreed = np.zeros(batch, bool)   # since the track settled or d last changed
        self.last_dt = np.zeros(batch)         # the last prediction's dt, q and Q
        self.last_q = np.zeros(batch)
        self.last_Q = np.zeros((batch, self.dim, self.dim))
        # pushes: the hold (process noise accel_noise_m_s2, the velocity of a
        # constant-velocity filter), and while the noise asks for a confirmation whether the
        # last detection may begin a push, its innovation, the consistency before it
        self.hold_until = np.full(batch, -np.inf)
        self.excess_pending = np.zeros(batch, bool)
        self.excess_y = np.zeros((batch, 2))
        self.excess_nis = np.ones(batch)
        self.beyond_t = np.full(batch, -np.inf)          # the last detection beyond maneuver_sigma
        self.fast: Optional[BatchBallKalman] = None
        if cfg.maneuver_hold_s > 0.0 and cfg.maneuver_sigma > 0.0:
            self.fast = BatchBallKalman(batch, cfg.constant_velocity())
        # the last frame's outcome per ball, and totals
        self.fresh = np.zeros(batch, bool)     # its detection was used
        self.gated = np.zeros(batch, bool)     # its detection was rejected as an outlier
        self.gated_count = np.zeros(batch, int)
        self.reset_count = np.zeros(batch, int)
        self.maneuver_count = np.zeros(batch, int)       # predictions widened for a push
        self.disturbance_changes = np.zeros(batch, int)  # changes of d found (less those undone)

    @property
    def gain(self) -> np.ndarray:
        """s per ball (the saved estimate between tracks)."""
        return np.where(self.init, self.x[:, GAIN_INDEX], self.saved_gain) if self.gain_state else np.ones(self.b)

    @property
    def disturbance_m_s2(self) -> np.ndarray:
        """d per ball (b, 2) [m/s^2] (the saved estimate between tracks; 0 without the state)."""
        if not self.disturbance_state:
            return np.zeros((self.b, 2))
        return np.where(self.init[:, None], self.x[:, D_INDEX:D_INDEX + 2], self.saved_d)

    def level_offset_rad(self, k_g: float) -> np.ndarray:
        """d as a plate-level offset per ball and axis (b, 2) [rad]: the tilt u at which the ball
        stays still, s k_g sin(u) = d, for the known acceleration -k_g sin(u)
        (PlateCommandInput.k_g)."""
        scale = (self.gain * k_g)[:, None]
        return np.arcsin(np.clip(self.disturbance_m_s2 / scale, -1.0, 1.0))

    def reset(self, mask) -> None:
        """Drop the tracks of the balls in mask: their next detection starts a new one."""
        mask = np.asarray(mask, bool)
        if not mask.any():
            return
        dropped = mask & self.init
        self.reset_count += dropped
        if self.gain_state:
            self.saved_gain = np.where(dropped, self.x[:, GAIN_INDEX], self.saved_gain)
            self.saved_gain_var = np.where(dropped, self.p[:, GAIN_INDEX, GAIN_INDEX], self.saved_gain_var)
        if self.disturbance_state:
            self.saved_d = np.where(dropped[:, None], self.x[:, D_INDEX:D_INDEX + 2], self.saved_d)
            self.saved_d_var = np.where(dropped, self.p[:, D_INDEX, D_INDEX], self.saved_d_var)
            self.change.clear(mask)
        for i in np.flatnonzero(mask):
            self.jump_tests.pop(int(i), None)
        self.init &= ~mask
        self.coasted[mask] = 0
        self.excess_pending[mask] = False

    def step(self, t: float, z: np.ndarray, det: np.ndarray, accel=None, lever=None, stepped=None):
        """Frame at stamp t: detections z (b, 2) [m] where det (b,) is set; accel (b, 2) the
        known accelerations [m/s^2] or None; lever (b, 2) the tilt's lever offsets
        (PlateCommandInput.lever_offset) or None: the part of the ball's plate-frame position
        the plate's tilt causes, which the filter takes from the detections and adds back to
        its position. `stepped` (b,): the balls this frame is for, which predict and, without a
        detection, coast (default det: a ball without a detection is not stepped, as a dropped
        frame). Returns (position (b, 2), velocity (b, 2), valid (b,)) after it; `fresh` and
        `gated` tell what became of each detection."""
        stepped = det if stepped is None else (stepped | det)
        z_model = z if lever is None else z - lever
        if self.noise is not None:
            self._adapt_noise(t, z_model, accel, det)
        fast_took = None
        if self.fast is not None:   # the push's hold: its velocity, and its state beyond the gate
            self.fast.r = self.r.copy()
            _, fast_vel, fast_valid = self.fast.step(t, z, det, stepped=stepped)
            fast_took = self.fast.fresh
        pos, vel, valid = self._step(t, z_model, det, stepped, accel, fast_took, lever)
        if self.fast is not None:
            use = valid & fast_valid & (t <= self.hold_until)
            vel[use] = fast_vel[use]
        if lever is not None:
            pos = pos + lever
        return pos, vel, valid

    def _step(self, t: float, z: np.ndarray, det: np.ndarray, stepped: np.ndarray, accel, fast_took, lever):
        dt = np.where(self.init, t - self.t_last, 0.0)
        self.reset(stepped & self.init & (dt > self.cfg.max_dt_s))
        pred = stepped & self.init & (dt > 0.0)   # a repeated or out-of-order stamp only updates
        if pred.any():
            self._predict(pred, np.where(pred, dt, 0.0), accel, t)
            self.t_last = np.where(pred, t, self.t_last)
        start = det & ~self.init
        if start.any():
            self._start(start, z, t)
        run = det & self.init & ~start
        coast = stepped & ~det & self.init
        self.fresh, self.gated = start.copy(), np.zeros(self.b, bool)
        if run.any():
            self._update(t, z, run, dt, accel, fast_took, lever)
        missed = coast | self.gated
        self.coasted = np.where(missed, self.coasted + 1, self.coasted)
        lost = missed & (self.coasted > self.cfg.max_coast_frames)
        valid = start | ((run | coast) & ~lost)
        self.reset(lost)
        return self.x[:, :2].copy(), np.where(valid[:, None], self.x[:, 2:4], 0.0), valid

    def _follow_push_beyond_gate(self, mask, lever) -> None:
        """The balls in mask, whose detection lies beyond the model's gate during a push's hold
        while the constant-velocity filter took it: a push faster than the gate lets the model
        follow (about 0.2 m/s at 30 Hz and 1 mm of noise). The ball's position and velocity, and
        their covariance, become the constant-velocity filter's; s and d stay the model's."""
        i = np.flatnonzero(mask)
        p = self.p[i]
        p[:, :4, :] = 0.0
        p[:, :, :4] = 0.0
        p[:, :4, :4] = self.fast.p[i, :4, :4]
        self.p[i] = p
        self.x[i, :4] = self.fast.x[i, :4]
        if lever is not None:
            self.x[i, :2] -= lever[i]
        self.coasted[i] = 0
        if self.disturbance_state:
            self.transition[i] = np.eye(self.dim)

    def _start(self, mask, z, t: float) -> None:
        i = np.flatnonzero(mask)
        self.x[i] = 0.0
        self.x[i, :2] = z[i]
        self.x[i, GAIN_INDEX] = self.saved_gain[i]
        self.p[i] = 0.0
        self.p[i, 0, 0] = self.p[i, 1, 1] = self.r[i]
        self.p[i, 2, 2] = self.p[i, 3, 3] = self.cfg.init_vel_std_m_s ** 2
        self.p[i, GAIN_INDEX, GAIN_INDEX] = self.saved_gain_var[i]
        if self.disturbance_state:
            self.x[i, D_INDEX:D_INDEX + 2] = self.saved_d[i]
            self.p[i, D_INDEX, D_INDEX] = self.p[i, D_INDEX + 1, D_INDEX + 1] = self.saved_d_var[i]
        self.transition[i] = np.eye(self.dim)
        self.track_start[i] = t
        self.model_has_agreed[i] = False
        self.init[i], self.coasted[i], self.t_last[i] = True, 0, t

    def _update(self, t: float, z, run, dt, accel, fast_took, lever) -> None:
        """The balls `run` (a track and a detection): the push test, the running consistency,
        the gate (beyond it, during a push's hold, the model follows the constant-velocity
        filter where that took the detection: `fast_took`), the change and jump tests of d, the
        update."""
        y = z - self.x[:, :2]
        inv, distance = innovation_inverse(self.p, self.r, y)
        if self.cfg.maneuver_sigma > 0.0:
            seen = run & (dt > 0.0)
            push, nis = seen & (distance > self.cfg.maneuver_sigma), self.nis
            self.beyond_t = np.where(push, t, self.beyond_t)
            push, nis = self._confirmed_pushes(seen, push, y, distance)
            agreed = push & (nis <= MODEL_AGREED_NIS)   # a model that agreed until the push began
            self.hold_until = np.where(agreed, t + self.cfg.maneuver_hold_s, self.hold_until)
            if self.disturbance_state and accel is not None:
                self._start_jump_tests(t, agreed)
            if push.any() and self._widen(push):
                inv, widened_distance = innovation_inverse(self.p, self.r, y)
                distance = np.where(push, widened_distance, distance)
        gate = self.cfg.gate_sigma
        if self.cfg.model_mismatch_time_constant_s > 0.0:   # a gated detection counts too, at the gate
            alpha = np.minimum(1.0, dt / self.cfg.model_mismatch_time_constant_s)
            self.nis = np.where(run, self.nis + alpha * (np.minimum(distance, gate) ** 2 / 2.0 - self.nis), self.nis)
        ok = run & (distance <= gate)
        follow = np.zeros(self.b, bool) if fast_took is None else run & ~ok & fast_took & (t <= self.hold_until)
        if follow.any():
            self._follow_push_beyond_gate(follow, lever)
        self.fresh |= ok | follow
        self.gated = run & ~ok & ~follow
        self.gated_count += self.gated
        if not ok.any():
            return
        appended = np.zeros(self.b, bool)
        if self.disturbance_state:
            appended, changed = self._find_disturbance_change(t, ok, y, accel is not None)
            if changed:                   # a change found corrected the state
                y = z - self.x[:, :2]
                inv, _ = innovation_inverse(self.p, self.r, y)
            ok = ok & ~self._decide_jumps(t, ok, z)
            appended &= ok                # a filter replaced starts its window again
        if not ok.any():
            return
        i = np.flatnonzero(ok)
        x_new, p_new, k = kalman_update(self.x[i], self.p[i], self.r[i], y[i], inv[i])
        self.x[i], self.p[i] = self._clamp_gain(x_new), p_new
        self.coasted[i] = 0
        if self.disturbance_state:
            self.change.set_last_gain(appended, k[appended[i]])
            self.transition[i] = np.eye(self.dim)

    def _find_disturbance_change(self, t: float, ok, y, known: bool):
        """Before the update of the balls `ok` (a detection within the gate, innovation y
        (b, 2)): their frame joins the change test's window (disturbance.ChangeTest), and a
        change the window showed, once it is sized, corrects the state and widens the
        covariance. Without a known acceleration d is not in the model, and during a push's
        hold the innovations are the push's: the window starts again. Returns the balls whose
        frame joined their window (their update's gain completes it) and whether any ball's
        state was corrected."""
        w = self.change
        if not known:
            w.clear(ok)
            return np.zeros(self.b, bool), False
        pushed = t <= self.hold_until
        w.clear(ok & pushed)
        add = ok & ~pushed
        if not add.any():
            return add, False
        changed = w.test(t, add, y, innovation_covariance(self.p, self.r), self._model_agrees(t), self.transition,
                         self.track_start)
        for i in np.flatnonzero(changed):
            frames = w.frames(i)
            # a detection beyond maneuver_sigma in the window that did not start a push's hold
            # (not confirmed under the noise, or the model had not agreed): a review, of the
            # filter as it is without the change, undoes the change if the frames that follow
            # show a push
            if self.beyond_t[i] >= frames[0].t:
                self.jump_tests[int(i)] = ChangeReview(self.x[i], self.p[i], float(self.r[i]), frames[:-1],
                                                       frames[-1].transition, t, D_INDEX, self.cfg.init_vel_std_m_s,
                                                       until=t + self.cfg.maneuver_hold_s)
            w.correct(i, t, self.x[i], self.p[i])
        self._count_changes(changed)
        return add & ~changed, bool(changed.any())

    def _count_changes(self, which) -> None:
        """The balls `which` (a mask or an index) had a change of d found: counted, and their
        model must agree again before the change test runs again."""
        self.disturbance_changes[which] += 1
        self.model_has_agreed[which] = False

    def _model_agrees(self, t: float) -> np.ndarray:
        """Per ball, whether its model has agreed with the detections for the change test: its
        settled consistency was at most MODEL_AGREED_NIS since its last change of d (a model
        that is still wrong after one would otherwise have d corrected window after window)."""
        self.model_has_agreed |= (self.nis <= MODEL_AGREED_NIS) & self.change.settled(t, self.track_start)
        return self.model_has_agreed.copy()

    def _start_jump_tests(self, t: float, pushed) -> None:
        """A jump test for each ball in `pushed` whose track has settled and has none yet: the
        reference filter from before the push's detection."""
        for i in np.flatnonzero(pushed & self.change.settled(t, self.track_start)):
            if int(i) not in self.jump_tests:
                self.jump_tests[int(i)] = JumpTest(self.x[i], self.p[i], float(self.r[i]), self.change.frames(i),
                                                   self.transition[i], t, D_INDEX, self.cfg.init_vel_std_m_s)

    def _decide_jumps(self, t: float, ok, z) -> np.ndarray:
        """The balls `ok` with a jump test fold their detection into it. When it finds a change
        of d, the reference filter, with the change's posterior (its mean and covariance given
        the frames since its onset, under the DISTURBANCE_STD_M_S2 prior) added, becomes the
        ball's filter, the push's hold ends and the change is reviewed until `maneuver_hold_s`
        after it, as a change the change test found is (ChangeReview.after: the decision is
        taken on the frames so far, and a push may still explain the ones that follow
        better); when it finds a push, the test ends and the hold goes on. Returns the balls
        whose filter was replaced (their detection is in it)."""
        adopted = np.zeros(self.b, bool)
        for i in [i for i in self.jump_tests if ok[i]]:
            test = self.jump_tests[i]
            after_change = test.taken == "force"
            if after_change:
                test.add_filtered(z[i] - self.x[i, :2], innovation_covariance(self.p[i], self.r[i]))
            x, P, r = test.x[None], test.P[None], np.array([test.r])
            y = z[i][None] - x[:, :2]
            inv, _ = innovation_inverse(P, r, y)
            test.add(y[0], innovation_covariance(P[0], test.r))
            x, P, K = kalman_update(x, P, r, y, inv)
            test.x, test.P = x[0], P[0]
            decision = test.take_up(K[0])
            if decision is None:
                continue
            del self.jump_tests[i]
            if decision == test.taken:
                continue     # what the filter took it for
            mean, covariance = test.posterior(decision)
            self.x[i], self.p[i], self.r[i] = self._clamp_gain((test.x + mean)[None])[0], test.P + covariance, test.r
            self.change.clear(i)
            self.transition[i] = np.eye(self.dim)
            self.coasted[i] = 0
            adopted[i] = True
            if after_change:          # a push: the change is undone, the model still agrees
                self.disturbance_changes[i] -= 1
                self.model_has_agreed[i] = True
            else:
                self.hold_until[i] = -np.inf
                self._count_changes(i)
                self.jump_tests[i] = ChangeReview.after(test, until=t + self.cfg.maneuver_hold_s)
        return adopted

    def _confirmed_pushes(self, seen, beyond, y, distance):
        """The balls with a detection `seen` (`beyond` maneuver_sigma) whose detection shows a
        push, and the consistency to judge its hold by. A push keeps pushing the detections the
        same way, noise scatters them: while the measurement noise is at least
        maneuver_confirm_noise_m a push needs a detection beyond maneuver_sigma and the next one
        pointing the same way beyond maneuver_confirm_sigma (or one beyond the gate). Below that
        noise a push moves the ball beyond the noise within a frame, and one detection tells."""
        single = self.r < self.cfg.maneuver_confirm_noise_m ** 2
        runs = seen & ~single
        goes_on = runs & self.excess_pending & (np.einsum("bi,bi->b", y, self.excess_y) > 0.0) \
            & (distance > self.cfg.maneuver_confirm_sigma)
        self.excess_nis = np.where(runs & ~goes_on, self.nis, self.excess_nis)
        self.excess_pending = np.where(runs, goes_on | beyond, self.excess_pending & ~(seen & single))
        self.excess_y = np.where(runs[:, None], y, self.excess_y)
        push = goes_on | (runs & (distance > self.cfg.gate_sigma))
        return np.where(single, beyond, push), np.where(single, self.nis, self.excess_nis)

    def _widen(self, mask) -> bool:
        """Add to the last prediction of the balls in mask the process noise it would have had
        without a known acceleration (a push or a hand on the ball: the model did not see it
        coming). Returns whether any was widened."""
        h = self.last_dt
        extra = np.maximum(self.sigma_a ** 2 - self.last_q, 0.0)
        mask = mask & (h > 0.0) & (extra > 0.0)
        if not mask.any():
            return False
        i = np.flatnonzero(mask)
        p = self.p[i]
        add_white_acceleration(p, extra[i], h[i])
        self.p[i] = p
        self.maneuver_count += mask
        return True

    def _adapt_noise(self, t: float, z, accel, det) -> None:
        """The measurement noise of the balls with a detection `det`: their detections' scatter
        (with the known acceleration times s removed), within [meas_noise_m, meas_noise_max_m]."""
        self.noise.add(t, z, None if accel is None else accel * self.gain[:, None], det)
        sigma = self.noise.sigma(det)
        ready = np.isfinite(sigma)
        self.r[ready] = np.clip(sigma[ready], self.noise_min, self.noise_max) ** 2

    def _predict(self, mask, dt, accel, t: float) -> None:
        """The prediction of the balls in mask over dt (b,) (the module's prediction and
        process_noise), and of their jump tests' reference filters with the model's own
        process noise."""
        i = np.flatnonzero(mask)
        h = dt[i]
        known = accel is not None
        a = accel[i] if known else None
        q = process_noise(self.nis[i], known, t <= self.hold_until[i], self.cfg)
        self.last_dt[i], self.last_q[i] = h, q
        f, Q = prediction(h, q, a, self.dim, GAIN_INDEX, self.cfg.input_gain_rate_per_s if self.gain_state else 0.0,
                          D_INDEX if self.disturbance_state else None, self.q_d)
        self.last_Q[i] = Q
        if self.disturbance_state:
            self.transition[i] = f @ self.transition[i]
        self.x[i] = np.einsum("bij,bj->bi", f, self.x[i])
        self.p[i] = self._clamp_gain_variance(f @ self.p[i] @ f.transpose(0, 2, 1) + Q)
        for k in [k for k, ball in enumerate(i) if int(ball) in self.jump_tests]:
            ball = int(i[k])
            test = self.jump_tests[ball]
            if t > (self.hold_until[ball] if test.taken == "push" else test.until):   # undecided: as taken
                del self.jump_tests[ball]
                continue
            q_model = process_noise(self.nis[[ball]], known, False, self.cfg)
            F, Q = prediction(h[[k]], q_model, None if a is None else a[[k]], self.dim, GAIN_INDEX,
                              self.cfg.input_gain_rate_per_s if self.gain_state else 0.0, D_INDEX, self.q_d)
            test.x = F[0] @ test.x
            test.P = self._clamp_gain_variance(F @ test.P[None] @ F.transpose(0, 2, 1) + Q)[0]
            test.predict(t, F[0])

    def _clamp_gain(self, x: np.ndarray) -> np.ndarray:
        """States x (m, n) with s within input_gain_bounds (held at 1 without its estimate)."""
        low, high = self.cfg.input_gain_bounds
        x[:, GAIN_INDEX] = np.clip(x[:, GAIN_INDEX], low, high) if self.gain_state else 1.0
        return x

    def _clamp_gain_variance(self, P: np.ndarray) -> np.ndarray:
        if self.gain_state:
            P[:, GAIN_INDEX, GAIN_INDEX] = np.minimum(P[:, GAIN_INDEX, GAIN_INDEX], self.gain_var_max)
        return P


class BallKalman:
    """Tracks one ball with the settings `cfg`; `step()` once per frame with the frame's stamp,
    with or without a detection (BatchBallKalman, a batch of one)."""

    def __init__(self, cfg: KalmanConfig):
        self.cfg = cfg
        self.filter = BatchBallKalman(1, cfg)
        self.disturbance_state = self.filter.disturbance_state
        self.dim = self.filter.dim

    def step(self, t: float, z: Optional[Tuple[float, float]],
             accel: Optional[Tuple[float, float]] = None,
             lever: Optional[Tuple[float, float]] = None) -> TrackEstimate:
        """Advance to stamp t (s) and fold in detection z (m) if any; accel in m/s^2 or None.
        lever (m; PlateCommandInput.lever_offset): the part of the ball's plate-frame position
        the plate's tilt causes at t. The filter tracks the rest (the rolling the known
        acceleration explains) and adds it back to its position estimate. Without a usable
        detection the estimate coasts; an invalid one keeps the last position with zero
        velocity."""
        det = np.array([z is not None])
        pos, vel, valid = self.filter.step(
            t, np.array([(0.0, 0.0) if z is None else z], dtype=float), det,
            None if accel is None else np.array([accel], dtype=float),
            None if lever is None else np.array([lever], dtype=float), stepped=np.ones(1, bool))
        f = self.filter
        return TrackEstimate(float(pos[0, 0]), float(pos[0, 1]), float(vel[0, 0]), float(vel[0, 1]),
                             bool(f.fresh[0]), bool(valid[0]), bool(f.gated[0]))

    def reset(self) -> None:
        """Drop the track: the next detection starts a new one."""
        self.filter.reset(np.ones(1, bool))

    @property
    def x(self) -> np.ndarray:
        """The state [x, y, vx, vy, s] (+ [d_x, d_y]) of the current or last track."""
        return self.filter.x[0]

    @property
    def meas_noise_m(self) -> float:
        """The measurement noise (1 sigma per axis, m) in use."""
        return float(np.sqrt(self.filter.r[0]))

    def process_noise(self, known_accel: bool, holding: bool = False) -> float:
        """q [m^2/s^4] of the next prediction (the module's process_noise)."""
        return float(process_noise(self.filter.nis, known_accel, holding, self.cfg)[0])

    @property
    def nis(self) -> float:
        """The running mean of the normalised innovation squared, per axis (1: the model holds)."""
        return float(self.filter.nis[0])

    @property
    def input_gain(self) -> float:
        """s: the acceleration the ball shows per unit of the known one (1 without the estimate)."""
        return float(self.filter.gain[0])

    @property
    def disturbance_m_s2(self) -> Tuple[float, float]:
        """d: the ball's acceleration the known one does not explain [m/s^2] (0 without the state)."""
        d = self.filter.disturbance_m_s2[0]
        return float(d[0]), float(d[1])

    def level_offset_rad(self, k_g: float) -> Tuple[float, float]:
        """d as a plate-level offset per axis [rad] (BatchBallKalman.level_offset_rad)."""
        u = self.filter.level_offset_rad(k_g)[0]
        return float(u[0]), float(u[1])

    @property
    def gated_count(self) -> int:
        """Detections rejected as outliers (total)."""
        return int(self.filter.gated_count[0])

    @property
    def reset_count(self) -> int:
        """Tracks dropped (total)."""
        return int(self.filter.reset_count[0])

    @property
    def maneuver_count(self) -> int:
        """Predictions widened for a push (total)."""
        return int(self.filter.maneuver_count[0])

    @property
    def disturbance_changes(self) -> int:
        """Changes of d found (total), less those a review took for a push."""
        return int(self.filter.disturbance_changes[0])
