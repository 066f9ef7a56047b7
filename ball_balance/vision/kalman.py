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
of the ball's velocity and as a jump of d, each at the onset that fits it best
(vision/disturbance.py JumpTest). As soon as one explanation is better by the change test's
bound, it stands: a change of d ends the hold and the reference filter, corrected by the
change, takes over.

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
from ball_balance.vision.disturbance import (
    DISTURBANCE_STD_M_S2,
    MODEL_AGREED_NIS,
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
    says (a wrong delay or gain). During a maneuver hold (`holding`) at least
    `maneuver_accel_noise_m_s2` squared."""
    nis = np.asarray(nis, dtype=float)
    sigma_a, sigma_cmd = cfg.accel_noise_m_s2, cfg.cmd_accel_noise_m_s2
    if not known_accel:
        q = np.full(nis.shape, sigma_a ** 2)
    elif cfg.model_mismatch_time_constant_s > 0.0:
        q = np.minimum(np.maximum(nis, 1.0), max(1.0, (sigma_a / sigma_cmd) ** 2)) * sigma_cmd ** 2
    else:
        q = np.full(nis.shape, sigma_cmd ** 2)
    return np.where(holding, np.maximum(q, cfg.maneuver_accel_noise_m_s2 ** 2), q)


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
        for last, value in ((self.t, np.full(self.b, t)), (self.z, z), (self.a, a)):
            last[newer] = np.roll(last[newer], -1, axis=1)
            last[newer, 2] = value[newer]
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
        self._disturbance = (np.zeros(2), 0.0)   # kept over dropped tracks
        self._change = ChangeTest(1, self.dim, self.d_index, consistency_settle_s(cfg.model_mismatch_time_constant_s)) \
            if self.disturbance_state else None
        self._track_start_s = 0.0
        self.disturbance_changes = 0  # changes of d found (total)
        # after a push's detection, until it decides: was it a push or a change of d?
        self._jump_test: Optional[JumpTest] = None
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
        self._hold_until = -np.inf     # during which process_noise keeps maneuver_accel_noise_m_s2
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
        if self._change is not None:
            self._change.clear()

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
        a = None if accel is None else np.asarray(accel, dtype=np.float64)
        F, Q = prediction(np.array([dt]), np.array([q]), None if a is None else a[None], self.dim,
                          4 if self.gain_state else None, self.gain_rate,
                          self.d_index if self.disturbance_state else None, self.q_d)
        F, Q = F[0], Q[0]
        if main and self.disturbance_state:
            self._transition = F @ self._transition
        kf.F, kf.Q = F, Q
        if self.gain_state:
            kf.predict()
            kf.P[4, 4] = min(kf.P[4, 4], self._gain_var_max)
        elif a is None:
            kf.predict()
        else:
            I2 = np.eye(2)
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
        """q (m^2/s^4) for the next prediction (the module's process_noise)."""
        return float(process_noise([self.nis], known_accel, holding, self.cfg)[0])

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
                        self._jump_test = JumpTest(self.kf, self._change.frames(0), self._transition, t,
                                                   self.d_index)
                self._widen_last_prediction()
                distance = self.mahalanobis(z)
            if self.model_mismatch_time_constant_s > 0.0:   # a gated detection counts too, at the gate
                alpha = min(1.0, dt_step / self.model_mismatch_time_constant_s)
                self.nis += alpha * (min(distance, self.gate_sigma) ** 2 / 2.0 - self.nis)
            if distance <= self.gate_sigma:
                in_window = self.disturbance_state and \
                    self._find_disturbance_change(t, z, known=accel is not None, pushed=t <= self._hold_until)
                if self._jump_test is not None and self._decide_jump(t, z):
                    return self._estimate(fresh=True, valid=True)
                self.kf.update(np.asarray(z, dtype=np.float64))
                if self.disturbance_state:
                    if in_window:
                        self._change.set_last_gain([True], self.kf.K[None])
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

    def _find_disturbance_change(self, t: float, z: Tuple[float, float], known: bool, pushed: bool) -> bool:
        """Before the update with detection z: its frame joins the change test's window
        (disturbance.ChangeTest), and a change the window shows corrects the state and widens
        the covariance. Without a known acceleration d is not in the model, and during a push's
        hold the innovations are the push's: the window starts again. Returns whether the frame
        is in the window (its update's gain completes it)."""
        if not known or pushed:
            self._change.clear()
            return False
        kf = self.kf
        innovation = np.asarray(z, dtype=np.float64) - kf.H @ kf.x
        S = kf.H @ kf.P @ kf.H.T + kf.R
        changed = self._change.test(t, np.ones(1, bool), innovation[None], S[None], np.array([self.nis]),
                                    self._transition[None], np.array([self._track_start_s]))
        if not changed[0]:
            return True
        self._change.correct(0, t, kf.x, kf.P)
        self.disturbance_changes += 1
        return False

    def _clamp_gain(self, kf: KalmanFilter) -> None:
        """Keep kf's input gain s within input_gain_bounds (after an update)."""
        if self.gain_state:
            kf.x[4] = min(max(kf.x[4], self.gain_bounds[0]), self.gain_bounds[1])

    def _settled(self, t: float) -> bool:
        """Whether the running consistency at t describes the detections rather than its start
        value: the track is CONSISTENCY_SETTLE_TIME_CONSTANTS of its time constant old. Until
        then neither a change of d nor a force behind a push is looked for."""
        return bool(self._change.settled(t, self._track_start_s))

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
        self._change.clear()
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
