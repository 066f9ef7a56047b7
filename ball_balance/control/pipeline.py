"""One control tick, shared by both nodes and the closed-loop benchmark (no ROS):

    safety -> latency prediction -> reference -> PID | MPC -> wiring + IK -> shaping -> guard

`ControlPipeline.step(now_s, obs, q_measured)` returns a `TickResult` with the 6 joint
positions to command, the tilt pair, the mode and what was used to get there. The caller
owns time: ROS time in the nodes, simulated time in the benchmark (lock-stepped).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ball_balance.control.kinematics import PlateKinematics
from ball_balance.control.mpc import MpcConfig, PlateMpc, preview
from ball_balance.control.pid import PidGains, PlatePid
from ball_balance.control.prediction import DelayEstimator, TiltHistory, predict
from ball_balance.control.references import Reference, RefSample
from ball_balance.control.safety import BallObservation, Mode, SafetyConfig, SafetySupervisor


@dataclass(frozen=True)
class PipelineConfig:
    controller: str = "pid"                 # "pid" | "mpc"
    k_g: float = 0.6 * 9.81                 # rolling factor * g [m/s^2 per rad]
    control_period_s: float = 0.02
    latency_compensation: bool = True
    actuation_delay_s: float = 0.03         # command -> plate tilt (arm + controller); initial value
    estimate_delay: bool = True             # refine actuation_delay_s online from the measured joints
    max_prediction_s: float = 0.3           # never extrapolate further than this
    reference_resume_s: float = 2.0         # re-engaging within this of a loss continues the reference
    pid: PidGains = field(default_factory=PidGains)
    mpc: MpcConfig = field(default_factory=MpcConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)


@dataclass
class TickResult:
    q_cmd: np.ndarray               # (6,) joint positions [rad]
    u: tuple                        # (u_x, u_y) commanded tilt [rad]
    mode: Mode
    ref: Optional[RefSample]        # reference used (None when not engaged)
    predicted: Optional[np.ndarray]  # (4,) x, y, vx, vy after latency compensation
    refused: bool = False           # the guard rejected a non-finite/out-of-limit command


class ControlPipeline:
    def __init__(self, cfg: PipelineConfig, kinematics: PlateKinematics, reference: Reference):
        self.cfg, self.kin, self.reference = cfg, kinematics, reference
        self.safety = SafetySupervisor(cfg.safety)
        self.pid = PlatePid(cfg.pid, cfg.k_g)
        self.mpc = PlateMpc(cfg.mpc) if cfg.controller == "mpc" else None
        self.history = TiltHistory()
        self.delay = DelayEstimator(cfg.actuation_delay_s, cfg.control_period_s)
        self.q_cmd: Optional[np.ndarray] = None
        self.u = np.zeros(2)
        self.t_engaged = 0.0
        self.t_last_active = -math.inf   # last tick ENGAGED or HOLDING
        self.refused_count = 0

    def set_reference(self, reference: Reference) -> None:
        self.reference = reference

    def set_pid_gains(self, gains: PidGains) -> None:
        self.pid.set_gains(gains)

    def reset_controllers(self) -> None:
        self.pid.reset()
        if self.mpc is not None:
            self.mpc.reset()
        self.history.clear()

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
        if mode in (Mode.ENGAGED, Mode.HOLDING):
            self.t_last_active = now_s
        ref = predicted = None
        if mode == Mode.ENGAGED or (mode == Mode.HOLDING and self._only_late(obs)):
            # a late but otherwise good state: keep controlling on its prediction (capped at
            # max_prediction_s); anything worse: hold the last tilt until the grace period ends
            ref, predicted = self._control(now_s, obs)
        elif mode != Mode.HOLDING:
            self.u = np.zeros(2)
        if mode in (Mode.ENGAGED, Mode.HOLDING):
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
        if self.cfg.estimate_delay and q_measured is not None and np.all(np.isfinite(q_measured)):
            self.delay.add(tilt_cmd, self.kin.tilt_of(q_measured))
        return TickResult(q_new.copy(), (float(self.u[0]), float(self.u[1])), mode, ref, predicted, refused)

    def _only_late(self, obs: Optional[BallObservation]) -> bool:
        """The state is usable except for its age (so prediction can bridge the gap)."""
        if obs is None or not obs.tracking_valid or obs.markers_found < self.cfg.safety.min_markers:
            return False
        return all(math.isfinite(v) for v in (obs.x, obs.y, obs.vx, obs.vy, obs.age_s))

    def _control(self, now_s: float, obs: BallObservation):
        cfg = self.cfg
        pos = np.array([obs.x, obs.y])
        vel = np.array([obs.vx, obs.vy])
        delay = self.actuation_delay_s
        if cfg.latency_compensation:
            stamp = now_s - obs.age_s
            horizon = min(now_s + delay, stamp + cfg.max_prediction_s)
            pos, vel = predict(pos, vel, stamp, horizon, self.history, cfg.k_g, delay)
        t_ref = now_s - self.t_engaged + (delay if cfg.latency_compensation else 0.0)
        ref = self.reference.sample(t_ref)
        if self.mpc is not None:
            p, v, a = preview(self.reference, t_ref, cfg.mpc.dt_s, cfg.mpc.horizon)
            u = self.mpc.solve(pos, vel, p, v, a, self.u)
        else:
            u = self.pid.step(pos, vel, ref, cfg.control_period_s)
        u = np.asarray(u, dtype=float)
        if np.all(np.isfinite(u)):
            self.u = u
        return ref, np.concatenate([pos, vel])
