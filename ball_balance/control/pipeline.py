"""One control tick, shared by both nodes and the closed-loop benchmark (no ROS):

    safety -> latency prediction -> reference -> tilt law -> wiring + IK -> shaping -> guard

`ControlPipeline.step(now_s, obs, q_measured)` returns a `TickResult` with the 6 joint
positions to command, the tilt pair, the mode and what was used to get there. The caller
owns time: ROS time in the nodes, simulated time in the benchmark (lock-stepped).

The tilt law is pluggable: anything with the `TiltLaw` shape (`reset()`, and
`tilt(ctx) -> (u_x, u_y)` for one tick's `TiltContext`) registered under a name in
`TILT_LAWS` and chosen by `PipelineConfig.controller`. "pid" and "mpc" are built in; a
registry entry may also be a "module:attribute" string, imported the first time that law
is built, so a law living elsewhere ("policy": `ball_balance.policy.tilt_law:make_tilt_law`)
costs nothing until used. A factory takes the `PipelineConfig` (its `law_params` holds the
node's validated parameter values, for a law's own parameters) and returns the law.
"""
from __future__ import annotations

import importlib
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, Mapping, Optional, Protocol, Tuple, Union

import numpy as np

from ball_balance.control.estimation import EstimatorConfig, PlantEstimator, level_offset_rad
from ball_balance.control.kinematics import PlateKinematics
from ball_balance.control.mpc import MpcConfig, PlateMpc, preview
from ball_balance.control.pid import PidGains, PlatePid
from ball_balance.control.prediction import DelayEstimator, TiltHistory, predict
from ball_balance.control.references import Delayed, Reference, RefSample
from ball_balance.control.safety import BallObservation, Mode, SafetyConfig, SafetySupervisor


@dataclass(frozen=True)
class PipelineConfig:
    controller: str = "pid"                 # a key of TILT_LAWS: "pid" | "mpc" | "policy"
    k_g: float = 0.6 * 9.81                 # rolling factor * g [m/s^2 per rad]
    control_period_s: float = 0.02
    latency_compensation: bool = True
    actuation_delay_s: float = 0.03         # command -> plate tilt (arm + controller); initial value
    estimate_delay: bool = True             # refine actuation_delay_s online from the measured joints
    delay_min_window_s: float = 0.6         # commands stored before the first delay estimate
    max_prediction_s: float = 0.3           # never extrapolate further than this
    reference_resume_s: float = 2.0         # re-engaging within this of a loss continues the reference
    engage_accel_m_s2: float = 0.2          # at a fresh engagement, lead the ball in from where it is (0: off)
    max_tilt_rad: float = 0.15              # per-axis tilt limit of the pipeline's own commands (braking)
    brake_on_loss_s: float = 0.6            # after losing the ball, brake its dead-reckoned motion this long (0: hold)
    brake_time_constant_s: float = 0.2      # braking decelerates the predicted velocity with this time constant
    pid: PidGains = field(default_factory=PidGains)
    mpc: MpcConfig = field(default_factory=MpcConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)  # online k_g and disturbance
    law_params: Mapping[str, Any] = field(default_factory=dict)  # validated node parameters, for a law's own


@dataclass(frozen=True)
class TiltContext:
    """What a tilt law gets for one tick (plate frame, SI units)."""

    now_s: float                    # controller time
    t_ref_s: float                  # reference time (since engagement, + the delay looked ahead)
    pos_m: np.ndarray               # (2,) ball position after latency compensation
    vel_m_s: np.ndarray             # (2,) ball velocity after latency compensation
    ref: RefSample                  # reference at t_ref_s (p, v, a)
    reference: Reference            # the whole reference (preview: reference.sample(t))
    u_prev: np.ndarray              # (2,) tilt commanded at the previous tick [rad]
    dt_s: float                     # control period
    k_g: float                      # plant gain in use: x'' = -k_g u + accel_offset [m/s^2 per rad]
    accel_offset_m_s2: np.ndarray   # (2,) constant disturbance acceleration in use
    obs: Optional[BallObservation] = None   # the raw observation behind pos/vel
    actuation_delay_s: float = 0.0  # command -> plate delay in use (the online estimate or the configured one)


class TiltLaw(Protocol):
    """A control law from the ball state to the plate tilt."""

    def reset(self) -> None:
        """Forget internal state (integrators, plans): called on every fresh engagement."""

    def tilt(self, ctx: TiltContext) -> Tuple[float, float]:
        """(u_x, u_y) [rad] for this tick; non-finite values are ignored by the pipeline."""


def adapted_pid_step(pid: PlatePid, k_g_tuned: float, scale_feedback: bool, pos_m, vel_m_s, ref: RefSample,
                     dt_s: float, k_g: float, accel_offset_m_s2) -> Tuple[float, float]:
    """One PID step with the plant estimate in use (k_g, accel_offset_m_s2): the PID law of the
    pid node, and the base of the learned policy's correction (policy/tilt_law.py)."""
    # the estimate sets the feed-forward (-a_ref / k_g) and cancels the disturbance (d / k_g)
    ref = RefSample(ref.p, ref.v, np.asarray(ref.a) * (k_g_tuned / k_g))
    # the feedback keeps its tuned tilt per metre on a weaker plant (scaled up, it moves the
    # loop toward the plant's non-minimum-phase zero sqrt(g / h), which falls with g, and the
    # plate shakes hard enough to make the ball hop at half gravity); on a stronger plant
    # (adapt_pid_feedback) it is scaled down to the acceleration per metre it was tuned for
    scale = min(1.0, k_g_tuned / k_g) if scale_feedback else 1.0
    return pid.step(pos_m, vel_m_s, ref, dt_s, gain_scale=scale, u_bias_rad=np.asarray(accel_offset_m_s2) / k_g)


class PidLaw:
    """The per-axis PID (control/pid.py) as a tilt law."""

    def __init__(self, cfg: PipelineConfig):
        self.pid = PlatePid(cfg.pid, cfg.k_g)
        self.k_g = cfg.k_g   # the k_g the gains were tuned for
        self.scale_feedback = bool(cfg.law_params.get("adapt_pid_feedback", False))

    def reset(self) -> None:
        self.pid.reset()

    def tilt(self, ctx: TiltContext) -> Tuple[float, float]:
        return adapted_pid_step(self.pid, self.k_g, self.scale_feedback, ctx.pos_m, ctx.vel_m_s, ctx.ref, ctx.dt_s,
                                ctx.k_g, ctx.accel_offset_m_s2)


class MpcLaw:
    """The two-axis MPC (control/mpc.py) as a tilt law, previewing the reference."""

    def __init__(self, cfg: PipelineConfig):
        self.mpc = PlateMpc(cfg.mpc)

    def reset(self) -> None:
        self.mpc.reset()

    def tilt(self, ctx: TiltContext) -> Tuple[float, float]:
        c = self.mpc.cfg
        p, v, a = preview(ctx.reference, ctx.t_ref_s, c.dt_s, c.horizon)
        return self.mpc.solve(ctx.pos_m, ctx.vel_m_s, p, v, a, ctx.u_prev, gain_ratio=ctx.k_g / c.k_g,
                              offset_rad=ctx.accel_offset_m_s2 / c.k_g)


LawFactory = Callable[[PipelineConfig], TiltLaw]
TILT_LAWS: Dict[str, Union[LawFactory, str]] = {
    "pid": PidLaw,
    "mpc": MpcLaw,
    "policy": "ball_balance.policy.tilt_law:make_tilt_law",
}
CONTROLLERS = tuple(TILT_LAWS)


def register_tilt_law(name: str, factory: Union[LawFactory, str]) -> None:
    """Make `PipelineConfig(controller=name)` build its law with `factory` (or "module:attr")."""
    TILT_LAWS[name] = factory


def make_tilt_law(cfg: PipelineConfig) -> TiltLaw:
    """The tilt law `cfg.controller` names; ValueError names the known ones."""
    factory = TILT_LAWS.get(cfg.controller)
    if factory is None:
        raise ValueError(f"unknown controller '{cfg.controller}': expected one of {sorted(TILT_LAWS)}")
    if isinstance(factory, str):
        module, _, attr = factory.partition(":")
        try:
            factory = getattr(importlib.import_module(module), attr)
        except (ImportError, AttributeError) as error:
            raise ValueError(f"controller '{cfg.controller}' is not available ({factory}: {error})") from None
    return factory(cfg)


@dataclass
class TickResult:
    q_cmd: np.ndarray               # (6,) joint positions [rad]
    u: tuple                        # (u_x, u_y) commanded tilt [rad]
    mode: Mode
    ref: Optional[RefSample]        # reference used: at now + the actuation delay (None when not engaged)
    predicted: Optional[np.ndarray]  # (4,) x, y, vx, vy after latency compensation
    refused: bool = False           # the guard rejected a non-finite/out-of-limit command
    # the reference at this tick's own time (x, y) [m], what /ball_reference publishes with the
    # tick's stamp: `ref` is ahead of it by the look-ahead, so a ball on a moving target would
    # seem to trail it by that much. The reference as given, without the lead-in from the ball
    # after an engagement, so that errors measured against it are the benchmark's (None when
    # not engaged)
    target_m: Optional[tuple] = None
    # what /plate_cmd carries for the tracker's Kalman feed-forward: the commanded tilt less the
    # estimated disturbance's level offset asin(d / k_g), the tilt that gives the ball the
    # acceleration the plant estimate expects (-k_g u + d). A commanded tilt that cancels a
    # disturbance barely moves the ball; fed that tilt, the tracker's filter expects the ball
    # to run off and reports it short of where it is. Always set by ControlPipeline.step
    plate_cmd: Optional[tuple] = None


class ControlPipeline:
    def __init__(self, cfg: PipelineConfig, kinematics: PlateKinematics, reference: Reference):
        self.cfg, self.kin, self.reference = cfg, kinematics, reference
        self.safety = SafetySupervisor(cfg.safety)
        self.law = make_tilt_law(cfg)
        self.history = TiltHistory()
        self.delay = DelayEstimator(cfg.actuation_delay_s, cfg.control_period_s,
                                    min_window_s=cfg.delay_min_window_s)
        self.plant = PlantEstimator(cfg.estimator, cfg.k_g)
        self._last_stamp = -math.inf
        self._last_good = None            # (stamp, pos, vel) of the last state controlled on
        self._t_lost: Optional[float] = None   # first tick without a usable state after control
        self.q_cmd: Optional[np.ndarray] = None
        self.u = np.zeros(2)
        self.t_engaged = 0.0
        self.t_last_active = -math.inf   # last tick ENGAGED or HOLDING
        # the reference the law follows: self.reference, led in from the ball's position after a
        # fresh engagement (engage_accel_m_s2); None until the first state after one
        self._tracked: Optional[Reference] = reference
        self.refused_count = 0
        self._tracker_level = False      # the last state carried the tracker's level offset

    def set_reference(self, reference: Reference) -> None:
        self.reference = reference
        self._tracked = reference

    @property
    def mpc(self) -> Optional[PlateMpc]:
        """The MPC behind the tilt law (its solve times, fallbacks), None for other laws."""
        return getattr(self.law, "mpc", None)

    @property
    def pid(self) -> Optional[PlatePid]:
        return getattr(self.law, "pid", None)

    def set_pid_gains(self, gains: PidGains) -> None:
        if self.pid is not None:
            self.pid.set_gains(gains)

    def reset_controllers(self) -> None:
        self.law.reset()
        self.plant.reset()   # (the tilt history stays: it is what the plate did, braking predicts with it)

    @property
    def actuation_delay_s(self) -> float:
        """Command -> plate delay in use: the online estimate, or the configured value."""
        return self.delay.estimate_s if self.cfg.estimate_delay else self.cfg.actuation_delay_s

    def at_home(self) -> bool:
        tol = self.cfg.safety.home_tolerance_rad
        return self.q_cmd is not None and float(np.max(np.abs(self.q_cmd - self.kin.home_q))) < tol

    def step(self, now_s: float, obs: Optional[BallObservation],
             q_measured: Optional[np.ndarray] = None) -> TickResult:
        """One control tick at time now_s. obs.age_s = now_s - capture stamp."""
        if self.q_cmd is None:
            start = q_measured if q_measured is not None and np.all(np.isfinite(q_measured)) else self.kin.home_q
            self.q_cmd = np.array(start, dtype=float)
        mode = self.safety.update(now_s, obs, self.at_home())
        if self.safety.reset_requested:
            self.reset_controllers()
            if mode == Mode.ENGAGED and now_s - self.t_last_active > self.cfg.reference_resume_s:
                self.t_engaged = now_s   # a fresh start: the reference begins again
                if self.cfg.engage_accel_m_s2 > 0.0:
                    self._tracked = None  # led in from the ball at the first state
        if mode in (Mode.ENGAGED, Mode.HOLDING):
            self.t_last_active = now_s
        ref = predicted = target = None
        braking = False
        if mode == Mode.ENGAGED or (mode == Mode.HOLDING and self.safety.usable_except_age(obs)):
            # a late but otherwise good state: keep controlling on its prediction (capped at
            # max_prediction_s)
            ref, predicted = self._control(now_s, obs)
            target_p = self.reference.sample(now_s - self.t_engaged).p   # the user's, not the lead-in
            target = (float(target_p[0]), float(target_p[1]))
            self._t_lost = None
        elif mode in (Mode.HOLDING, Mode.RETURNING):
            # the ball is lost: brake its predicted motion for a bounded time, then level (a
            # ball rolling on a circle would roll off a plate that goes level at once)
            if self._t_lost is None:
                self._t_lost = now_s
            brake = self._brake(now_s)
            braking = brake is not None
            if braking:
                self.u, predicted = brake
            elif mode == Mode.RETURNING or self.cfg.brake_on_loss_s > 0:
                self.u = np.zeros(2)
            # (braking off: HOLDING holds the last tilt until loss_hold_s ends)
        else:
            self.u = np.zeros(2)
        if mode in (Mode.ENGAGED, Mode.HOLDING) or braking:
            q_target = self.kin.ik(self.q_cmd, self.kin.desired_rotation(*self.u))
        else:
            q_target = self.kin.home_q
        q_new = self.kin.shape(q_target, self.q_cmd)
        refused = not (np.all(np.isfinite(q_new)) and np.all(q_new >= self.kin.q_min)
                       and np.all(q_new <= self.kin.q_max))
        if refused:
            self.refused_count += 1
            q_new = self.q_cmd.copy()
        self.q_cmd = q_new
        # What the plate was told, after shaping (step limit, tilt limit): the prediction's input
        tilt_cmd = self.kin.tilt_of(q_new) if mode != Mode.HOMING else (0.0, 0.0)
        self.history.record(now_s, *tilt_cmd)
        if q_measured is not None and np.all(np.isfinite(q_measured)):
            tilt_measured = self.kin.tilt_of(q_measured)
            if self.cfg.estimate_delay:
                self.delay.add(tilt_cmd, tilt_measured)
            self.plant.add_tilt(now_s, tilt_measured)   # the tilt the ball really felt
        else:
            self.plant.add_tilt(now_s + self.actuation_delay_s, tilt_cmd)
        # the tracker's filter expects -k_g u + d: with an estimate of d of its own it takes the
        # tilt as commanded; else the tilt less the level offset of the controller's estimate
        level = np.zeros(2) if self._tracker_level else level_offset_rad(self.plant.offset, self.plant.k_g)
        plate_cmd = (float(self.u[0] - level[0]), float(self.u[1] - level[1]))
        return TickResult(q_new.copy(), (float(self.u[0]), float(self.u[1])), mode, ref, predicted, refused, target,
                          plate_cmd)

    def _brake(self, now_s: float):
        """(tilt, predicted state) that decelerates the last good state's motion, dead-reckoned
        over the tilts since then; None once brake_on_loss_s has passed since the loss."""
        cfg = self.cfg
        if self._last_good is None or self._t_lost is None or now_s - self._t_lost >= cfg.brake_on_loss_s:
            return None
        stamp, pos, vel = self._last_good
        k_g, offset = self.plant.k_g, self.plant.offset
        delay = self.actuation_delay_s
        pos, vel = predict(pos, vel, stamp, now_s + delay, self.history, k_g, delay, offset)
        # x'' = -k_g u + d = -v / tau
        u = (vel / cfg.brake_time_constant_s + offset) / k_g
        u = np.clip(u, -cfg.max_tilt_rad, cfg.max_tilt_rad)
        return u, np.concatenate([pos, vel])

    def _lead_in(self, obs: BallObservation) -> Reference:
        """The reference led in from the ball's position: a smoothstep from there into the
        reference (references.Delayed), long enough that its acceleration, 6 d / T^2 at the start
        for a distance d, stays within engage_accel_m_s2. Without the lead-in, a ball far from
        the reference would get full tilt at once, before the delay and plant estimates have any
        data, and a strong plant with a long unknown delay would throw it off the plate."""
        ball = np.array([obs.x, obs.y])
        distance_m = float(np.linalg.norm(self.reference.sample(0.0).p - ball))
        lead_s = math.sqrt(6.0 * distance_m / self.cfg.engage_accel_m_s2)
        return Delayed(self.reference, 0.0, ball, lead_s) if lead_s > 0.0 else self.reference

    def _control(self, now_s: float, obs: BallObservation):
        cfg = self.cfg
        pos = np.array([obs.x, obs.y])
        vel = np.array([obs.vx, obs.vy])
        delay = self.actuation_delay_s
        stamp = now_s - obs.age_s
        self._tracker_level = obs.level_offset_rad is not None
        if self._tracker_level:
            self.plant.take_level_offset(obs.level_offset_rad)
        if stamp > self._last_stamp:   # a new ball state: one more sample for the plant estimate
            self._last_stamp = stamp
            self.plant.add_state(stamp, pos)
        self._last_good = (stamp, pos.copy(), vel.copy())
        k_g, offset = self.plant.k_g, self.plant.offset.copy()
        if cfg.latency_compensation:
            horizon = min(now_s + delay, stamp + cfg.max_prediction_s)
            pos, vel = predict(pos, vel, stamp, horizon, self.history, k_g, delay, offset)
        if self._tracked is None:
            self._tracked = self._lead_in(obs)
        t_ref = now_s - self.t_engaged + (delay if cfg.latency_compensation else 0.0)
        ref = self._tracked.sample(t_ref)
        ctx = TiltContext(now_s=now_s, t_ref_s=t_ref, pos_m=pos, vel_m_s=vel, ref=ref, reference=self._tracked,
                          u_prev=self.u.copy(), dt_s=cfg.control_period_s, k_g=k_g,
                          accel_offset_m_s2=offset, obs=obs, actuation_delay_s=delay)
        u = np.asarray(self.law.tilt(ctx), dtype=float)
        if np.all(np.isfinite(u)):
            self.u = u
        return ref, np.concatenate([pos, vel])
