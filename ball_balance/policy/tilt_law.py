"""The learned tilt law: the PID plus the policy's bounded correction, one control tick at a time.

    u = clamp(u_pid + blend(t) * weight(error) * delay_share(delay) * scale * policy(observation), low, high)

`blend` ramps from 0 to 1 over `blend_s` after every (re-)engagement, so switching the policy
in never jumps the plate. `weight` fades the correction out far from the reference or in only
away from it or on a weak plant, as the model was trained (its metadata's
`correction_fade_error_m`, `correction_onset_error_m` and `correction_low_gain_onset`;
observation.correction_weight). `delay_share` keeps the policy out where the command-to-plate
delay is longer than `max_delay_s` (policy_max_delay_s): an operating limit, not part of the model.
A non-finite observation or model output never reaches the command: the law holds its last
tilt and counts it (`held_count`).
"""
from __future__ import annotations

import math
from typing import Mapping, Optional

import numpy as np

from ball_balance.control.pid import PidGains, PlatePid
from ball_balance.control.pipeline import adapted_pid_step
from ball_balance.policy.observation import ObservationBuilder, correction_weight, flat_names
from ball_balance.policy.params import model_path
from controller_manager_py.controllers.policy_model import PolicyModelError, PolicyRunner

ACTION_KIND = "residual_tilt"
DELAY_FADE_S = 0.02   # the correction fades out over this much delay beyond max_delay_s


def delay_share(delay_s: float, max_delay_s: float) -> float:
    """1 up to max_delay_s of command-to-plate delay, 0 from max_delay_s + DELAY_FADE_S, linear
    between (max_delay_s 0: always 1)."""
    if max_delay_s <= 0.0:
        return 1.0
    return min(1.0, max(0.0, (max_delay_s + DELAY_FADE_S - delay_s) / DELAY_FADE_S))


class PolicyTiltLaw:
    """A pipeline tilt law (ball_balance.control.pipeline.TiltLaw): `reset()`, `tilt(ctx)`."""

    def __init__(self, runner: PolicyRunner, gains: PidGains, k_g: float, blend_s: float = 1.0,
                 scale_feedback: bool = False, use_estimate: bool = True, max_delay_s: float = 0.0):
        self.runner, self.k_g, self.blend_s, self.max_delay_s = runner, k_g, blend_s, max_delay_s
        # as the model was trained (a model whose metadata lacks one: none)
        self.correction_fade_m = float(runner.metadata.training.get("correction_fade_error_m", 0.0))
        self.correction_onset_m = float(runner.metadata.training.get("correction_onset_error_m", 0.0))
        self.low_gain_onset = float(runner.metadata.training.get("correction_low_gain_onset", 0.0))
        self.scale_feedback = scale_feedback   # adapt_pid_feedback, as the PID law
        self.use_estimate = use_estimate       # the PID takes the plant estimate (as the model was trained)
        self.pid = PlatePid(gains, k_g)
        self.builder = ObservationBuilder(1, runner.metadata.observation.history)
        self.u = np.zeros(2)
        self.t_active_s = 0.0
        self.held_count = 0          # ticks that held the last tilt (non-finite input or output)
        self.inferences = 0
        self.last_inference_s = 0.0
        self.last_correction = np.zeros(2)

    def reset(self) -> None:
        """A new engagement: forget the history, start the blend again."""
        self.pid.reset()
        self.builder.reset()
        self.u = np.zeros(2)
        self.t_active_s = 0.0

    @property
    def blend(self) -> float:
        return 1.0 if self.blend_s <= 0.0 else min(1.0, self.t_active_s / self.blend_s)

    def tilt(self, ctx):
        """One tick of the pipeline (TiltContext): the PID's tilt plus the policy's correction."""
        age = ctx.obs.age_s if ctx.obs is not None else 0.0
        if not self.use_estimate:
            return self.step(ctx.pos_m, ctx.vel_m_s, ctx.ref, ctx.dt_s, age, delay_s=ctx.actuation_delay_s)
        return self.step(ctx.pos_m, ctx.vel_m_s, ctx.ref, ctx.dt_s, age, ctx.k_g, ctx.accel_offset_m_s2,
                         ctx.actuation_delay_s)

    def step(self, pos_m, vel_m_s, ref, dt_s: float, age_s: float = 0.0, k_g: Optional[float] = None,
             accel_offset_m_s2=(0.0, 0.0), delay_s: float = 0.0):
        """(u_x, u_y) [rad] for the (latency-predicted) ball state and the reference sample.
        k_g, accel_offset_m_s2: the pipeline's plant estimate, which the PID uses as the PID law
        does (None: the configured k_g, no disturbance). delay_s: the command-to-plate delay in
        use (delay_share)."""
        pos, vel = np.asarray(pos_m, dtype=float), np.asarray(vel_m_s, dtype=float)
        scale_feedback = self.scale_feedback and k_g is not None
        u_pid = np.asarray(adapted_pid_step(self.pid, self.k_g, scale_feedback, pos, vel, ref, dt_s,
                                            self.k_g if k_g is None else k_g, accel_offset_m_s2), dtype=float)
        gain_ratio = 1.0 if k_g is None else k_g / self.k_g
        obs = self.builder.build((pos - ref.p)[None], (vel - ref.v)[None], (-np.asarray(ref.a) / self.k_g)[None],
                                 u_pid[None], age_s, gain_ratio)
        action = self.runner.infer(obs[0])
        self.last_inference_s = self.runner.last_inference_s
        if action is None or not np.all(np.isfinite(u_pid)):
            self.held_count += 1
            self.builder.record_tilt(self.u)
            return float(self.u[0]), float(self.u[1])
        self.inferences += 1
        action = self.blend * delay_share(delay_s, self.max_delay_s) * action
        if self.correction_fade_m > 0.0 or self.correction_onset_m > 0.0:   # nothing to compute without either
            action = correction_weight((pos - ref.p)[None], self.correction_fade_m, self.correction_onset_m, gain_ratio,
                                       self.low_gain_onset)[0] * action
        self.last_correction = action * self.runner.scale
        self.u = self.runner.command(action, base=u_pid)
        self.builder.record_tilt(self.u)
        self.t_active_s += dt_s
        return float(self.u[0]), float(self.u[1])


def base_pid_mismatch(training: Mapping, values: Mapping) -> Optional[str]:
    """The first PID parameter the configuration sets differently from the one the residual was
    trained on top of, as 'name: model X, configured Y', or None."""
    for name, trained in (training.get("base_pid") or {}).items():
        if name in values and not math.isclose(float(values[name]), float(trained), rel_tol=1e-9, abs_tol=1e-12):
            return f"{name}: model {trained}, configured {values[name]}"
    return None


def load_tilt_law(values: Mapping) -> PolicyTiltLaw:
    """The law for validated controller parameters (POLICY_SCHEMA); PolicyModelError, one line,
    when the model does not fit them."""
    from ball_balance.control import config as control_config

    runner = PolicyRunner.load(model_path(values["policy_model"]), observation_names=flat_names(),
                               action_kind=ACTION_KIND, action_count=2, rate_hz=values["control_rate_hz"])
    mismatch = base_pid_mismatch(runner.metadata.training, values)
    if mismatch:
        raise PolicyModelError(f"policy model {runner.where}: trained on a different PID ({mismatch})")
    # a model trained on a PID that took the plant estimate records the estimate's parameters
    # (ball_balance/policy/env.py BASE_PID_KEYS); a model that records none runs on the PID without it
    base_pid = runner.metadata.training.get("base_pid") or {}
    use_estimate = "adapt_plant_gain" in base_pid
    gains = control_config.pid_gains(values)
    return PolicyTiltLaw(runner, gains, control_config.k_g(values), values["policy_blend_s"],
                         bool(values.get("adapt_pid_feedback", False)), use_estimate, values["policy_max_delay_s"])


def make_tilt_law(cfg) -> PolicyTiltLaw:
    """The pipeline's factory (TILT_LAWS["policy"]): the node's parameters are cfg.law_params."""
    if "policy_model" not in cfg.law_params:
        raise PolicyModelError("controller 'policy' needs the policy parameters (POLICY_SCHEMA: policy_model, "
                               "policy_blend_s)")
    return load_tilt_law(cfg.law_params)
