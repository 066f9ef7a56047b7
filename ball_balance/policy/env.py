"""Vectorised training plant: many ball-on-plate episodes stepped at once in numpy (no ROS, no torch).

It models what stands between the controller and the ball in the MuJoCo simulation, at the
rates the closed-loop benchmark uses (ball_balance/benchmark/episode.py):

    camera 30 Hz (the benchmark's EpisodeSpec.camera_rate_hz; frames dropped with
    frame_drop_prob) -> detection noise -> the tracker's Kalman filter as it runs
    (vision/kalman.py BatchBallKalman, the tracker's own over the batch: its config, the
    commanded tilt as known acceleration with its gain estimated, adaptive process and
    measurement noise, the disturbance state d) -> visible
    vision_delay_s later -> control tick 60 Hz (the PID node's rate; config/policy.yaml):
    online plant estimate (k g, and the tracker's d as the constant disturbance: the
    pipeline's own, control/estimation.py's BatchPlantEstimator, a plate per episode) ->
    latency prediction over the state's age with that estimate -> the PID as the pid node
    runs it (control/pid.py's own law over the batch; schema defaults, the estimate in its
    feed-forward, disturbance tilt and feedback scale)
    + policy correction -> shaping (tilt-rate limit per tick, total tilt limit) ->
    camera-to-command latency -> servo lag ->
    plate tilt -> x'' = -k g sin(tilt + bias)

randomised per episode over `DomainRanges` (wider than the benchmark's extreme_dr). Each
episode also knows the truth (`teacher_tilt`): the state predicted exactly over its own
latency and servo lag, and the true k g, which a PD law turns into the tilt a controller
with perfect knowledge would command: the label the policy learns to approximate from
what it can observe.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import NamedTuple, Optional

import numpy as np

from ball_balance.config_values import controller_values, tracker_values
from ball_balance.control import config as control_config
from ball_balance.control.estimation import BatchPlantEstimator
from ball_balance.control.pid import Pid
from ball_balance.control.prediction import predict_batch
from ball_balance.plate_geometry import GRAVITY_M_S2, PLATE_SIDE_M, ROLLING_FACTOR_SHELL, ROLLING_FACTOR_SOLID
from ball_balance.policy.observation import ObservationBuilder, correction_weight, low_gain_share
from ball_balance.sim.config import CAMERA_RATE_HZ, FAST_NOISE_FLOOR_M, VISION_DELAY_S
from ball_balance.vision.kalman import BatchBallKalman, KalmanConfig

# the control tick: the PID node's rate (config/pid.yaml, 60 Hz); config/policy.yaml's
# control_rate_hz must equal it (checked here) and the model records it (rate_hz, checked at run time)
CONTROL_DT_S = 1.0 / 60.0
SUBSTEPS = 4                          # the plant's integration steps per tick (a whole number)
SUBSTEP_S = CONTROL_DT_S / SUBSTEPS
REFERENCES = ("stationary", "circle", "figure_eight")
# the privileged law whose tilt is the label (PlateBatch.teacher_tilt): "pid" the PID itself on
# the true state with the true gain and bias, "pd" a stiffer PD law (wn, zeta) on the true state,
# "mpc" the MPC's unconstrained first move (config/mpc.yaml) on the true state, gain and bias,
# "pid_mpc" the PID teacher near the reference and the MPC on the controller's own estimate far
# from it (after a push: the MPC brings the ball back sooner), blended per axis on the error;
# "mpc_far" the same with the running PID itself near the reference (no correction there): every
# label a function of what the controller sees
TEACHERS = ("pid", "pd", "mpc", "pid_mpc", "mpc_far")
# the PID parameters the residual is trained on top of (recorded in the model, checked at run time)
BASE_PID_KEYS = ("kp", "ki", "kd", "i_limit_rad", "antiwindup_time_s", "max_tilt_cmd_rad",
                 "rolling_factor", "gravity_m_s2", "derivative_filter_s", "adapt_pid_feedback",
                 "adapt_plant_gain", "adapt_disturbance", "adapt_time_constant_s", "adapt_window_s",
                 "actuation_delay_s", "estimate_actuation_delay")

# the tracker's filter parameters the plant models (recorded in the model's training metadata)
TRACKER_FILTER_KEYS = ("meas_noise_m", "accel_noise_m_s2", "init_vel_std_m_s", "gate_sigma", "max_coast_frames",
                       "max_dt_s", "use_plate_cmd", "plate_cmd_timeout_s", "plate_cmd_delay_s",
                       "estimate_plate_cmd_delay",
                       "cmd_accel_noise_m_s2", "estimate_input_gain", "input_gain_bounds", "input_gain_std",
                       "input_gain_rate_per_s", "model_mismatch_time_constant_s", "adaptive_meas_noise",
                       "meas_noise_max_m",
                       "meas_noise_window_frames", "maneuver_sigma", "maneuver_hold_s",
                       "maneuver_confirm_sigma", "maneuver_confirm_noise_m", "tilt_lever_m",
                       "rolling_factor", "disturbance_time_constant_s")


class MpcFirstMove(NamedTuple):
    """The MPC of config/mpc.yaml as the linear law of its unconstrained first move
    (PlateMpc.first_move_gains): v_0 = z . state_gain + prev_gain v_prev in the model's tilt."""

    horizon: int                # N: reference preview steps
    state_gain: np.ndarray      # (2 + 3N,) on z = [p0, v0, ref_p (N), ref_v (N), ref_a (N)]
    prev_gain: float            # on the previous tilt
    k_g: float                  # the model's gain [m/s^2 per rad]
    u_max_rad: float            # tilt limit
    du_max_rad: float           # tilt change per tick


@dataclass(frozen=True)
class DomainRanges:
    """Uniform ranges (low, high) drawn per episode; every one covers the benchmark's extreme_dr."""

    gravity_scale: tuple = (0.35, 1.8)
    solid_ball_prob: float = 0.3          # rolling factor 5/7 instead of 3/5
    latency_s: tuple = (0.0, 0.22)        # camera-to-command latency added to the commands
    detection_noise_m: tuple = (0.0, 0.006)
    frame_drop_prob: tuple = (0.0, 0.12)
    servo_lag_s: tuple = (0.003, 0.02)
    tilt_step_rad: tuple = (0.018, 0.024)  # tilt change per control tick the joint-step limit allows
    tilt_bias_rad: tuple = (-0.004, 0.004)  # plate not quite level at the commanded tilt
    gain_error: tuple = (0.93, 1.07)       # unmodelled rolling losses, slip
    release_radius_m: tuple = (0.0, 0.11)
    release_speed_m_s: tuple = (0.0, 0.15)
    push_prob_per_s: float = 0.15         # random pushes (disturbance rejection; the benchmark's pushes
    #                                       domain pushes every 4 s)
    push_speed_m_s: tuple = (0.05, 0.2)

    def as_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


@dataclass(frozen=True)
class Nominal:
    """What the controllers assume. `Nominal.from_config()` reads them where they are set (the
    policy's parameters). The tracker's filter is read from config/ball_tracker.yaml over the
    tracker's schema (`tracker_config()`)."""

    k_g: float = ROLLING_FACTOR_SHELL * GRAVITY_M_S2
    u_max_rad: float = 0.15
    max_total_tilt_rad: float = 0.20
    vision_delay_s: float = VISION_DELAY_S
    max_prediction_s: float = 0.5
    fast_noise_floor_m: float = FAST_NOISE_FLOOR_M   # the benchmark's fast mode: never less
    camera_rate_hz: float = CAMERA_RATE_HZ

    @classmethod
    def from_config(cls) -> Nominal:
        """The policy's parameters; the camera's rate, vision delay and noise floor are the
        defaults, the closed-loop benchmark's episodes' (sim/config.py)."""
        values = controller_values("policy", "stationary")
        return cls(k_g=control_config.k_g(values), u_max_rad=values["max_tilt_cmd_rad"],
                   max_total_tilt_rad=values["max_total_tilt_rad"], max_prediction_s=values["max_prediction_s"])


def tracker_config():
    """The tracker's parameters as the benchmark and the node run them (config/ball_tracker.yaml
    over the schema's defaults)."""
    from ball_balance.vision.config import TrackerConfig

    return TrackerConfig.from_values(tracker_values())


def reference_table(kind: str, n_ticks: int) -> np.ndarray:
    """(n_ticks, 3, 2): p, v, a of the benchmark's reference `kind` at every control tick
    (the same Reference objects and parameters the pipeline builds)."""
    ref = control_config.reference(controller_values("pid", kind))
    out = np.zeros((n_ticks, 3, 2))
    for n in range(n_ticks):
        s = ref.sample(n * CONTROL_DT_S)
        out[n] = (s.p, s.v, s.a)
    return out


class PlateBatch:
    """`batch` episodes of `duration_s`, stepped together. Use:

        env = PlateBatch(256, seed); obs = env.reset()
        while not env.finished: obs = env.step(action)   # action (batch, 2) in [-1, 1] or None
    """

    def __init__(self, batch: int, seed: int, ranges: DomainRanges = DomainRanges(),
                 nominal: Optional[Nominal] = None, duration_s: float = 20.0, action_scale_rad: float = 0.1,
                 teacher_wn: float = 4.0, teacher_zeta: float = 0.85, tracker_cfg=None, teacher: str = "pid",
                 pid_overrides=(), correction_fade_m: float = 0.0, teacher_far_m: float = 0.008,
                 correction_onset_m: float = 0.0, low_gain_onset: float = 0.0):
        if teacher not in TEACHERS:
            raise ValueError(f"teacher = {teacher!r} must be one of {TEACHERS}")
        self.b, self.ranges, self.teacher = batch, ranges, teacher
        self.nom = Nominal.from_config() if nominal is None else nominal
        self.rng = np.random.default_rng(seed)
        self.n_ticks = int(round(duration_s / CONTROL_DT_S))
        self.action_scale = action_scale_rad
        # observation.correction_weight, as the runtime applies it
        self.correction_fade_m, self.correction_onset_m = correction_fade_m, correction_onset_m
        self.wn, self.zeta = teacher_wn, teacher_zeta
        self.teacher_far_m = teacher_far_m   # pid_mpc, mpc_far: the near label within it, the MPC's beyond twice it
        # pid_mpc, mpc_far: the MPC's label near the reference too on a weak plant, and the correction
        # applied there (observation.low_gain_share of the plant estimate's gain ratio; 0: not)
        self.low_gain_onset = low_gain_onset
        # the PID under the policy: config/policy.yaml over the schema (pid_overrides: (name, value) pairs
        # over those, to try another base; a model is refused unless the configuration matches it)
        self.pid_values = controller_values("policy", "stationary", tuple(pid_overrides))
        self.estimator_cfg = control_config.estimator_config(self.pid_values)
        self.scale_feedback = bool(self.pid_values["adapt_pid_feedback"])
        if not self.pid_values["latency_compensation"]:
            raise ValueError("the training plant predicts the state as the pipeline does with latency_compensation")
        if not np.isclose(self.pid_values["control_rate_hz"] * CONTROL_DT_S, 1.0):
            raise ValueError(f"the training plant steps at {1 / CONTROL_DT_S:.0f} Hz: control_rate_hz must be that")
        # the pipeline's command -> plate delay: predicted over besides the state's age, the
        # configured value or its online estimate (control/prediction.py DelayEstimator)
        self.delay_settings = self._delay_estimator()
        self.max_delay_s = max(self.pid_values["actuation_delay_s"],
                               self.delay_settings.max_lag * CONTROL_DT_S if self.pid_values["estimate_actuation_delay"]
                               else 0.0)
        self.mpc_law = self._mpc_first_move() if teacher in ("mpc", "pid_mpc", "mpc_far") else None
        # the teacher looks ahead up to its latency + lag (and the MPC's horizon beyond)
        pad = int(0.5 / CONTROL_DT_S) + 2 + (self.mpc_law.horizon if self.mpc_law else 0)
        self.refs = np.stack([reference_table(k, self.n_ticks + pad) for k in REFERENCES])   # (R, n, 3, 2)
        self.builder = ObservationBuilder(batch)
        self.tracker_cfg = tracker_config() if tracker_cfg is None else tracker_cfg
        # the known acceleration the tracker derives from /plate_cmd (the law's tilt)
        self.tracker_k_g = self.tracker_cfg.rolling_factor * GRAVITY_M_S2
        self.lever_m = float(self.tracker_cfg.tilt_lever_m)

    @staticmethod
    def _mpc_first_move() -> MpcFirstMove:
        """The MPC of config/mpc.yaml as the linear law of its first move, stepping at this
        plant's tick."""
        from ball_balance.control.mpc import PlateMpc

        cfg = control_config.pipeline_config(controller_values("mpc", "stationary"), "mpc").mpc
        if not np.isclose(cfg.dt_s, CONTROL_DT_S):
            raise ValueError(f"the MPC teacher steps at the plant's {1 / CONTROL_DT_S:.0f} Hz: config/mpc.yaml's "
                             f"control_rate_hz must be that")
        state_gain, prev_gain = PlateMpc(cfg).first_move_gains()
        return MpcFirstMove(cfg.horizon, state_gain, prev_gain, cfg.k_g, cfg.u_max_rad, cfg.du_max_rad_s * cfg.dt_s)

    def _delay_estimator(self, batch_shape=()):
        from ball_balance.control.prediction import DelayEstimator

        v = self.pid_values
        return DelayEstimator(v["actuation_delay_s"], CONTROL_DT_S, min_window_s=v["actuation_delay_min_window_s"],
                              batch_shape=batch_shape)

    @property
    def actuation_delay_s(self) -> np.ndarray:
        """The delay (b,) the pipeline predicts over besides the state's age (control/pipeline.py)."""
        if self.pid_values["estimate_actuation_delay"]:
            return self.delay.estimate_s
        return np.full(self.b, float(self.pid_values["actuation_delay_s"]))

    # ---- episode start ---------------------------------------------------------------
    def reset(self) -> np.ndarray:
        b, r, rng, n = self.b, self.ranges, self.rng, self.nom

        def u(lim, size=b):
            return rng.uniform(lim[0], lim[1], size)

        self.g_scale = u(r.gravity_scale)
        self.k_roll = np.where(rng.random(b) < r.solid_ball_prob, ROLLING_FACTOR_SOLID, ROLLING_FACTOR_SHELL)
        self.latency = u(r.latency_s)
        self.noise = np.maximum(u(r.detection_noise_m), n.fast_noise_floor_m)
        self.drop_p = u(r.frame_drop_prob)
        self.servo_lag = u(r.servo_lag_s)
        self.tilt_step = u(r.tilt_step_rad)
        self.bias = u(r.tilt_bias_rad, (b, 2))
        self.gain = u(r.gain_error, (b, 2))
        self.k_g_true = (self.k_roll * GRAVITY_M_S2 * self.g_scale)[:, None] * self.gain   # (b, 2)
        self.ref_kind = rng.integers(0, len(REFERENCES), b)
        radius, angle = u(r.release_radius_m), u((0.0, 2 * np.pi))
        speed, heading = u(r.release_speed_m_s), u((0.0, 2 * np.pi))
        self.x = np.stack([radius * np.cos(angle), radius * np.sin(angle)], 1)
        self.v = np.stack([speed * np.cos(heading), speed * np.sin(heading)], 1)
        self.theta = np.zeros((b, 2))          # plate tilt
        # the delay the tracker's filter looks the commands up with: with its online estimate
        # (estimate_plate_cmd_delay: the plate's tilt from the markers against the command history)
        # the episode's own command -> plate delay, latency + servo lag, as the estimate settles
        # on it (its first second on the start value is not modelled); else the configured value
        if self.tracker_cfg.estimate_plate_cmd_delay and self.tracker_cfg.use_plate_cmd:
            self.plate_cmd_delay_s = self.latency + self.servo_lag
        else:
            self.plate_cmd_delay_s = np.full(b, float(self.tracker_cfg.plate_cmd_delay_s))
        self.hist_len = int(np.ceil((max(r.latency_s[1] + r.servo_lag_s[1], self.tracker_cfg.plate_cmd_delay_s,
                                         self.max_delay_s)
                                     + max(Nominal.max_prediction_s, n.max_prediction_s)) / CONTROL_DT_S)) + 4
        self.cmd_hist = np.zeros((b, 2, self.hist_len))   # shaped commands by tick (ring, index tick % len)
        self.law_hist = np.zeros((b, 2, self.hist_len))   # the law's tilts (/plate_cmd) by tick
        self.cmd = np.zeros((b, 2))            # last shaped command
        self.u_law = np.zeros((b, 2))          # last law output
        # the tracker's filter; a fixed measurement noise stands in for one tuned to the
        # episode's noise (as the benchmark's fast mode does), an adaptive one starts from the config
        self.kalman = BatchBallKalman(b, KalmanConfig.from_tracker(self.tracker_cfg), fixed_meas_noise_m=self.noise)
        self.pending = []   # (visible_at, est x, est v, stamp, valid, tilt integrals, level offset)
        self.obs_x = np.zeros((b, 2))
        self.obs_v = np.zeros((b, 2))
        self.obs_stamp = np.full(b, np.nan)
        self.next_frame = 0.0
        self.tick = 0
        self.t_engaged = None
        self.alive = np.ones(b, bool)
        self.engaged = np.zeros(b, bool)
        self.last_push_s = np.full(b, -np.inf)
        self.sq_err = np.zeros(b)
        self.n_err = np.zeros(b)
        gains = replace(control_config.pid_gains(self.pid_values), u_max_rad=self.nom.u_max_rad)
        self.pid = Pid(gains, self.nom.k_g, (b, 2))
        self.delay = self._delay_estimator((b,))
        # the PID teacher's own integral and derivative filter, stepped every tick on the truth
        self.teacher_pid = Pid(gains, self.nom.k_g, (b, 2))
        self.u_teacher = np.zeros((b, 2))
        capacity = int(np.ceil(self.estimator_cfg.window_s * self.nom.camera_rate_hz)) + 8
        self.estimator = BatchPlantEstimator(b, self.estimator_cfg, self.nom.k_g, capacity)
        self.tilt_p = np.zeros((b, 2))         # double and single integral of the plate tilt reached
        self.tilt_v = np.zeros((b, 2))
        self.builder.reset()
        return self._observe()

    @property
    def finished(self) -> bool:
        return self.tick >= self.n_ticks or not self.alive.any()

    @property
    def time_s(self) -> float:
        return self.tick * CONTROL_DT_S

    # ---- sensing ---------------------------------------------------------------------
    def _camera(self) -> None:
        t = self.time_s
        while self.next_frame <= t + 1e-9:
            self.next_frame += 1.0 / self.nom.camera_rate_hz
            arrived = self.rng.random(self.b) >= self.drop_p
            z = self.x + self.rng.normal(0.0, 1.0, (self.b, 2)) * self.noise[:, None]
            # the ball's centre sits above the tilt axis: the plate's tilt moves its plate-frame
            # position by tilt_lever_m u (the tracker takes it out with the commanded tilt)
            z = z + self.lever_m * self.theta
            u_known = self._known_tilt(t)
            accel = None if u_known is None else -self.tracker_k_g * np.sin(u_known)
            lever = None if u_known is None or self.lever_m == 0.0 else self.lever_m * u_known
            est_x, est_v, valid = self.kalman.step(t, z, arrived, accel, lever)
            # the tracker's d as its plate-level offset (/ball_level_offset), which the
            # pipeline's plant estimate takes as its disturbance
            level = self.kalman.level_offset_rad(self.tracker_k_g) if self.kalman.disturbance_state else None
            self.pending.append((t + self.nom.vision_delay_s, est_x, est_v, t, valid,
                                 self.tilt_p.copy(), self.tilt_v.copy(), level))
        while self.pending and self.pending[0][0] <= t + 1e-9:
            _, ex, ev, stamp, valid, tilt_p, tilt_v, level = self.pending.pop(0)
            self.obs_x[valid], self.obs_v[valid] = ex[valid], ev[valid]
            self.obs_stamp[valid] = stamp
            if level is not None:
                self.estimator.take_level_offset(np.where((valid & self.alive)[:, None], level, np.nan))
            # the pipeline adds each new state it controls on to the plant estimate
            self.estimator.add_state(np.full(self.b, stamp), ex, tilt_p, tilt_v, valid & self.alive)

    def _known_tilt(self, t):
        """What the tracker's PlateCommandInput takes at a frame stamped t (its acceleration is
        -k g sin(u), its lever offset tilt_lever_m u): the law's tilt in force the tracker's
        delay (plate_cmd_delay_s, per episode) before t (commands arrive once per tick, after
        the tick's frames), None before the first command, without use_plate_cmd or past the
        timeout."""
        cfg = self.tracker_cfg
        if not cfg.use_plate_cmd or self.tick == 0 or t - (self.tick - 1) * CONTROL_DT_S > cfg.plate_cmd_timeout_s:
            return None
        j = np.floor((t - self.plate_cmd_delay_s) / CONTROL_DT_S + 1e-9).astype(int)
        j = np.clip(j, max(0, self.tick - self.hist_len + 1), self.tick - 1)
        return self.law_hist[np.arange(self.b), :, j % self.hist_len]

    def _predicted_state(self):
        """The pipeline's latency prediction (control/prediction.py predict): the state at its
        stamp carried over the commanded tilts to now + the actuation delay (at most
        max_prediction_s past the stamp), the command issued at tick j acting from j dt + delay
        on; with the plant estimate's k g and disturbance."""
        t = self.time_s
        delay = self.actuation_delay_s
        have = np.isfinite(self.obs_stamp)
        stamp = np.where(have, self.obs_stamp, t)
        age = np.clip(t - stamp, 0.0, None)
        horizon = np.minimum(t + delay, stamp + self.nom.max_prediction_s)
        n_back = int(np.ceil((self.nom.max_prediction_s + self.max_delay_s) / CONTROL_DT_S)) + 2
        ticks = np.arange(max(self.tick - n_back, 0), self.tick)
        issued, tilts = ticks * CONTROL_DT_S, self.cmd_hist[:, :, ticks % self.hist_len].transpose(0, 2, 1)
        if self.tick < n_back:   # the plate is level before the first command
            issued, tilts = np.concatenate([[-np.inf], issued]), np.concatenate([np.zeros((self.b, 1, 2)), tilts], 1)
        x, v = predict_batch(self.obs_x, self.obs_v, stamp, horizon, issued, tilts, self.estimator.k_g, delay,
                             self.estimator.offset)
        return x, v, age

    def _observe(self) -> np.ndarray:
        self._camera()
        have = np.isfinite(self.obs_stamp)
        if self.t_engaged is None and have.any():
            self.t_engaged = self.tick
        self.engaged = have & self.alive
        x, v, age = self._predicted_state()
        ref = self._ref_ahead(self.actuation_delay_s)
        self.e, self.ve = x - ref[:, 0], v - ref[:, 1]
        self.a_ref = ref[:, 2]
        # the PID as the pipeline runs it (control/pipeline.py adapted_pid_step): the estimate
        # sets the feed-forward and the disturbance tilt, and scales the feedback down only
        k_est = self.estimator.k_g[:, None]
        scale = np.minimum(1.0, self.nom.k_g / k_est) if self.scale_feedback else 1.0
        self.u_pid = self.pid.step(self.e, self.ve, self.a_ref * (self.nom.k_g / k_est), CONTROL_DT_S,
                                   gain_scale=scale, u_bias_rad=self.estimator.offset / k_est)
        self.u_pid = np.where(self.engaged[:, None], self.u_pid, 0.0)
        self.age = np.where(have, age, 0.0)
        if self.teacher in ("pid", "pid_mpc"):
            self.u_teacher = self._pid_teacher()
        self.gain_ratio = self.estimator.k_g / self.nom.k_g
        return self.builder.build(self.e, self.ve, -self.a_ref / self.nom.k_g, self.u_pid, self.age, self.gain_ratio)

    def _ref(self, ahead_ticks) -> np.ndarray:
        """(b, 3, 2) reference p, v, a at this tick + ahead_ticks (per env array or int)."""
        n = self.tick - (self.t_engaged if self.t_engaged is not None else self.tick)
        idx = np.clip(n + np.asarray(ahead_ticks, dtype=int), 0, self.refs.shape[1] - 1)
        idx = np.broadcast_to(idx, (self.b,))
        return self.refs[self.ref_kind, idx]

    def _ref_ahead(self, ahead_s) -> np.ndarray:
        """(b, 3, 2) reference p, v, a ahead_s (b,) after this tick, linear between ticks."""
        whole = np.floor(np.asarray(ahead_s) / CONTROL_DT_S + 1e-9)
        frac = (np.asarray(ahead_s) / CONTROL_DT_S - whole)[:, None, None]
        return (1.0 - frac) * self._ref(whole) + frac * self._ref(whole + 1)

    # ---- the label -------------------------------------------------------------------
    def teacher_tilt(self) -> np.ndarray:
        """The label: the tilt (b, 2) a privileged law commands this tick (`teacher`)."""
        if self.teacher == "mpc":
            return self._mpc_teacher()
        if self.teacher in ("pid_mpc", "mpc_far"):
            far = np.clip(np.abs(self.e) / self.teacher_far_m - 1.0, 0.0, 1.0)
            if self.low_gain_onset > 0.0:
                far = np.maximum(far, low_gain_share(self.gain_ratio, self.low_gain_onset)[:, None])
            near_tilt = self.u_teacher if self.teacher == "pid_mpc" else self.u_pid
            return far * self._mpc_on_estimate() + (1.0 - far) * near_tilt
        return self.u_teacher if self.teacher == "pid" else self._pd_teacher()

    def _true_prediction(self):
        """The true state predicted exactly to when this tick's command reaches the plate
        (latency + servo lag), and the reference there: (x, v, ref (b, 3, 2))."""
        horizon = self.latency + self.servo_lag
        k_max = int(np.ceil(horizon.max() / SUBSTEP_S)) + 1
        k_each = np.round(horizon / SUBSTEP_S).astype(int)
        x, v, th = self.x.copy(), self.v.copy(), self.theta.copy()
        px, pv, pth = x.copy(), v.copy(), th.copy()
        for k in range(1, k_max + 1):
            tau = self.time_s + (k - 1) * SUBSTEP_S
            x, v, th = self._substep(x, v, th, tau, include_now=False)
            hit = (k_each == k)[:, None]
            px, pv, pth = np.where(hit, x, px), np.where(hit, v, pv), np.where(hit, th, pth)
        # the position as the tracker reports it: with the plate tilt's lever
        return px + self.lever_m * pth, pv, self._ref(np.round(horizon / CONTROL_DT_S))

    def _pid_teacher(self) -> np.ndarray:
        """The PID as the pipeline runs it, but on the true state predicted exactly over the
        latency and servo lag, with the true k g (feed-forward, feedback scale) and the true
        plate bias as its disturbance tilt: where the running PID's estimates are right the
        label equals its tilt and the correction to learn is zero."""
        x, v, ref = self._true_prediction()
        k_true = self.k_g_true
        scale = np.minimum(1.0, self.nom.k_g / k_true) if self.scale_feedback else 1.0
        u = self.teacher_pid.step(x - ref[:, 0], v - ref[:, 1], ref[:, 2] * (self.nom.k_g / k_true), CONTROL_DT_S,
                                  gain_scale=scale, u_bias_rad=-self.bias)
        return np.where(self.engaged[:, None], u, 0.0)

    def _pd_teacher(self) -> np.ndarray:
        """Tilt (b, 2) of a PD law on the true state predicted exactly to when this tick's
        command reaches the plate (latency + servo lag), with the true k g and plate bias."""
        px, pv, ref = self._true_prediction()
        e, ve = px - ref[:, 0], pv - ref[:, 1]
        acc = -self.wn ** 2 * e - 2 * self.zeta * self.wn * ve + ref[:, 2]
        u = -acc / self.k_g_true - self.bias
        return np.clip(u, -self.nom.u_max_rad, self.nom.u_max_rad)

    def _mpc_teacher(self) -> np.ndarray:
        """Tilt (b, 2) of the MPC on the true state predicted exactly to when this tick's command
        reaches the plate, previewing the reference from there, with the true k g and plate bias
        (the plant x'' = -k g (u + bias) is the model's tilt v = s (u + bias), s = true k g / the
        model's: PlateMpc.solve's gain ratio s and offset -s bias)."""
        px, pv, _ = self._true_prediction()
        base = np.round((self.latency + self.servo_lag) / CONTROL_DT_S).astype(int)
        preview = np.stack([self._ref(base + k) for k in range(1, self.mpc_law.horizon + 1)], axis=3)   # (b, 3, 2, N)
        s = self.k_g_true / self.mpc_law.k_g
        return self._mpc_tilt(px, pv, preview, s, -s * self.bias)

    def _mpc_on_estimate(self) -> np.ndarray:
        """Tilt (b, 2) of the MPC as the mpc node runs it: on this tick's latency-predicted
        estimate, the reference previewed from the actuation delay on, the plant estimate's gain
        and disturbance."""
        delay = self.actuation_delay_s
        ref = self._ref_ahead(delay)
        preview = np.stack([self._ref_ahead(delay + k * CONTROL_DT_S) for k in range(1, self.mpc_law.horizon + 1)],
                           axis=3)
        k_model = self.mpc_law.k_g
        return self._mpc_tilt(self.e + ref[:, 0], self.ve + ref[:, 1], preview,
                              (self.estimator.k_g / k_model)[:, None], self.estimator.offset / k_model)

    def _mpc_tilt(self, pos_m, vel_m_s, preview, gain_ratio, offset_rad) -> np.ndarray:
        """The MPC's unconstrained first move (PlateMpc.first_move_gains) for states (b, 2) and
        a reference preview (b, 3, 2, N), planned in the model's tilt v = s u - o (PlateMpc.solve)
        from the law's previous tilt, then clipped to the MPC's rate and tilt limits."""
        law = self.mpc_law
        z = np.concatenate([pos_m[..., None], vel_m_s[..., None], preview[:, 0], preview[:, 1], preview[:, 2]], axis=2)
        v = z @ law.state_gain + law.prev_gain * (gain_ratio * self.u_law - offset_rad)
        u = np.clip((v + offset_rad) / gain_ratio, self.u_law - law.du_max_rad, self.u_law + law.du_max_rad)
        return np.where(self.engaged[:, None], np.clip(u, -law.u_max_rad, law.u_max_rad), 0.0)

    def push_visible(self, frames: int) -> np.ndarray:
        """Per episode (b,): False from a push until `frames` camera frames captured after it
        can have reached the controller (frames camera periods + the vision delay). Before that
        the teacher, on the true state, already answers a push the controller cannot see: a
        label no observation explains (frames 0: always True)."""
        if frames <= 0:
            return np.ones(self.b, bool)
        return self.time_s - self.last_push_s >= frames / self.nom.camera_rate_hz + self.nom.vision_delay_s - 1e-9

    def residual_label(self, tilt: np.ndarray) -> np.ndarray:
        """The action in [-1, 1] that makes the law command `tilt`."""
        return np.clip((tilt - self.u_pid) / self.action_scale, -1.0, 1.0)

    # ---- dynamics --------------------------------------------------------------------
    def _target(self, tau, include_now=True):
        """Plate target at time tau: the command issued at the last tick <= tau - latency."""
        n = np.floor((tau - self.latency) / CONTROL_DT_S + 1e-9).astype(int)
        n = np.minimum(n, self.tick if include_now else self.tick - 1)
        idx = (np.maximum(n, 0) % self.hist_len)[:, None, None]
        tgt = np.take_along_axis(self.cmd_hist, np.broadcast_to(idx, (self.b, 2, 1)), axis=2)[..., 0]
        return np.where((n >= 0)[:, None], tgt, 0.0)

    def _substep(self, x, v, th, tau, include_now=True):
        h = SUBSTEP_S
        target = self._target(tau, include_now)
        th = th + (target - th) * np.minimum(1.0, h / self.servo_lag)[:, None]
        a = -self.k_g_true * np.sin(th + self.bias)
        v = v + a * h
        x = x + v * h
        return x, v, th

    def step(self, action: Optional[np.ndarray] = None, tilt: Optional[np.ndarray] = None) -> np.ndarray:
        """Apply the law: PID + action * scale * correction_weight (or an explicit `tilt`), shape,
        advance one tick."""
        if tilt is None:
            a = np.zeros((self.b, 2)) if action is None else np.clip(action, -1.0, 1.0)
            a = a * correction_weight(self.e, self.correction_fade_m, self.correction_onset_m, self.gain_ratio,
                                      self.low_gain_onset)[:, None]
            tilt = self.u_pid + self.action_scale * a
        u = np.clip(tilt, -self.nom.u_max_rad, self.nom.u_max_rad)
        u = np.where(self.engaged[:, None], u, 0.0)
        self.u_law = u
        self.law_hist[:, :, self.tick % self.hist_len] = u
        self.builder.record_tilt(u)
        # shaping: tilt change per tick limited (the joint-step limit), total tilt limited
        du = u - self.cmd
        norm = np.linalg.norm(du, axis=1, keepdims=True)
        du = du * np.minimum(1.0, self.tilt_step[:, None] * 1.1 / np.maximum(norm, 1e-12))
        du = np.clip(du, -self.tilt_step[:, None], self.tilt_step[:, None])
        cmd = self.cmd + du
        total = np.linalg.norm(cmd, axis=1, keepdims=True)
        cmd = cmd * np.minimum(1.0, self.nom.max_total_tilt_rad / np.maximum(total, 1e-12))
        self.cmd = cmd
        self.cmd_hist[:, :, self.tick % self.hist_len] = cmd
        if self.pid_values["estimate_actuation_delay"]:
            self.delay.add(cmd, self.theta)   # the measured joints' tilt at this tick
        t0 = self.time_s
        # the tilt reached, as the measured joints give it each tick (the plant estimate's input)
        self.tilt_p += self.tilt_v * CONTROL_DT_S + 0.5 * self.theta * CONTROL_DT_S ** 2
        self.tilt_v += self.theta * CONTROL_DT_S
        for k in range(SUBSTEPS):
            self.x, self.v, self.theta = self._substep(self.x, self.v, self.theta, t0 + k * SUBSTEP_S)
        # random pushes
        r = self.ranges
        push = self.rng.random(self.b) < r.push_prob_per_s * CONTROL_DT_S
        if push.any():
            speed = self.rng.uniform(*r.push_speed_m_s, self.b)
            ang = self.rng.uniform(0, 2 * np.pi, self.b)
            self.v += (push * speed)[:, None] * np.stack([np.cos(ang), np.sin(ang)], 1)
            self.last_push_s = np.where(push, t0 + CONTROL_DT_S, self.last_push_s)
        self.tick += 1
        half = PLATE_SIDE_M / 2.0
        self.alive &= np.all(np.abs(self.x) <= half, axis=1)
        if self.tick * CONTROL_DT_S > 5.0:
            ref = self._ref(0)[:, 0]
            err = np.sum((self.x - ref) ** 2, axis=1)
            self.sq_err += np.where(self.alive, err, 0.0)
            self.n_err += self.alive
        return self._observe()

    def rmse_steady_m(self) -> np.ndarray:
        """Per episode: RMS distance to the reference after 5 s (nan for a dropped episode)."""
        out = np.sqrt(self.sq_err / np.maximum(self.n_err, 1))
        return np.where(self.alive, out, np.nan)
