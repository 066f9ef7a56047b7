"""The vectorised training plant agrees with the controllers it stands in for."""
import dataclasses

import numpy as np
import pytest

from ball_balance.benchmark.episode import controller_values
from ball_balance.control import config as control_config
from ball_balance.policy.env import (
    CONTROL_DT_S,
    DomainRanges,
    PlateBatch,
)


def test_the_policy_is_trained_on_the_pid_nodes_pid():
    """One PID: the policy's parameters leave the PID to the schema's defaults, as the pid node."""
    policy, pid = controller_values("policy", "stationary"), controller_values("pid", "stationary")
    for name in ("kp", "ki", "kd", "i_limit_rad", "antiwindup_time_s", "derivative_filter_s",
                 "adapt_pid_feedback", "adapt_plant_gain", "adapt_disturbance",
                 "adapt_time_constant_s"):
        assert policy[name] == pid[name], name
    env = PlateBatch(2, seed=0, duration_s=1.0)
    env.reset()
    assert env.pid.gains == dataclasses.replace(control_config.pid_gains(pid), u_max_rad=env.nom.u_max_rad)
    assert env.pid.k_g == control_config.k_g(pid)
    assert env.estimator_cfg == control_config.estimator_config(policy)


def test_the_plant_steps_at_the_pid_nodes_rate_and_the_benchmarks_camera_rate():
    """The policy ticks as often as the PID node (config/pid.yaml), whole substeps per tick, and
    the plant's camera runs at the closed-loop benchmark's rate."""
    from ball_balance.benchmark.episode import EpisodeSpec
    from ball_balance.policy.env import SUBSTEP_S, SUBSTEPS, Nominal

    policy, pid = controller_values("policy", "stationary"), controller_values("pid", "stationary")
    assert policy["control_rate_hz"] == pid["control_rate_hz"]
    assert CONTROL_DT_S * policy["control_rate_hz"] == pytest.approx(1.0, abs=1e-12)
    assert SUBSTEPS * SUBSTEP_S == pytest.approx(CONTROL_DT_S, abs=1e-15)
    spec, nominal = EpisodeSpec(), Nominal.from_config()
    assert (nominal.camera_rate_hz, nominal.vision_delay_s, nominal.fast_noise_floor_m) == \
        (spec.camera_rate_hz, spec.vision_delay_s, spec.fast_noise_floor_m)


def test_plant_prediction_is_the_pipelines():
    """With an actuation delay estimated online, the plant predicts the state as
    control/prediction.py predict does over the same commanded tilts."""
    from ball_balance.control.prediction import TiltHistory, predict

    b = 6
    env = PlateBatch(b, 3, pid_overrides=(("actuation_delay_s", 0.03), ("estimate_actuation_delay", True)),
                     duration_s=5.0)
    env.reset()
    history = [TiltHistory(1000) for _ in range(b)]
    checked = 0
    while not env.finished:
        x, v, _ = env._predicted_state()
        for i in np.flatnonzero(np.isfinite(env.obs_stamp)):
            delay, stamp = env.actuation_delay_s[i], env.obs_stamp[i]
            horizon = min(env.time_s + delay, stamp + env.nom.max_prediction_s)
            p, pv = predict(env.obs_x[i], env.obs_v[i], stamp, horizon, history[i], env.estimator.k_g[i], delay,
                            env.estimator.offset[i])
            np.testing.assert_allclose(np.concatenate([x[i], v[i]]), np.concatenate([p, pv]), atol=1e-12)
            checked += 1
        env.step()
        for i in range(b):
            history[i].record((env.tick - 1) * CONTROL_DT_S, *env.cmd_hist[i, :, (env.tick - 1) % env.hist_len])
    assert checked > 200 * b
    # the estimate finds the episodes' camera-to-command latency plus servo lag
    np.testing.assert_allclose(env.actuation_delay_s, env.latency + env.servo_lag, atol=0.015)


def test_pid_teacher_is_the_pid_where_its_estimates_are_exact():
    """The PID teacher is the running PID on the true state: with no latency, noise, lag, bias
    or gain error its label stays close to the PID's own tilt (the correction to learn ~ 0)."""
    calm = DomainRanges(gravity_scale=(1.0, 1.0), solid_ball_prob=0.0, latency_s=(0.0, 0.0),
                        detection_noise_m=(0.0, 0.0), frame_drop_prob=(0.0, 0.0), servo_lag_s=(0.003, 0.003),
                        tilt_bias_rad=(0.0, 0.0), gain_error=(1.0, 1.0), push_prob_per_s=0.0)
    env = PlateBatch(8, seed=2, ranges=calm, duration_s=8.0, teacher="pid")
    env.reset()
    labels = []
    while not env.finished:
        if env.time_s > 3.0:
            labels.append(np.abs(env.teacher_tilt() - env.u_pid))
        env.step()
    assert env.alive.all() and np.mean(labels) < 0.0015


def test_mpc_teacher_is_the_mpcs_first_move_on_the_truth():
    """The MPC teacher is PlateMpc.solve on the true state predicted to the plate, the reference
    previewed from there, the true gain and bias, where no constraint is active."""
    from ball_balance.control.mpc import PlateMpc

    ranges = DomainRanges(gain_error=(1.0, 1.0), push_prob_per_s=0.0, release_speed_m_s=(0.0, 0.02))
    env = PlateBatch(6, seed=3, ranges=ranges, duration_s=3.0, teacher="mpc")
    env.reset()
    while env.time_s < 2.0:
        env.step(tilt=env.teacher_tilt())
    tilt = env.teacher_tilt()
    cfg = control_config.pipeline_config(controller_values("mpc", "stationary"), "mpc").mpc
    px, pv, _ = env._true_prediction()
    base = np.round((env.latency + env.servo_lag) / CONTROL_DT_S).astype(int)
    checked = 0
    for i in range(env.b):
        preview = np.stack([env._ref(base + k)[i] for k in range(1, cfg.horizon + 1)])   # (N, 3, 2)
        mpc = PlateMpc(cfg)
        s = env.k_g_true[i, 0] / cfg.k_g
        u = mpc.solve(px[i], pv[i], preview[:, 0], preview[:, 1], preview[:, 2], env.u_law[i], gain_ratio=s,
                      offset_rad=-s * env.bias[i])
        if mpc.unconstrained:
            np.testing.assert_allclose(tilt[i], u, atol=1e-9)
            checked += 1
    assert checked >= 4


def test_pid_mpc_teacher_is_the_pid_teacher_near_and_the_mpc_on_the_estimate_far():
    from ball_balance.control.mpc import PlateMpc

    ranges = DomainRanges(push_prob_per_s=0.0, release_radius_m=(0.03, 0.1))
    env = PlateBatch(8, seed=5, ranges=ranges, duration_s=3.0, teacher="pid_mpc", teacher_far_m=0.008)
    env.reset()
    near_seen = far_seen = unconstrained = 0
    cfg = control_config.pipeline_config(controller_values("mpc", "stationary"), "mpc").mpc
    while not env.finished:
        tilt = env.teacher_tilt()
        near, far = np.abs(env.e) <= 0.008, np.abs(env.e) >= 0.016
        near &= env.engaged[:, None]
        far &= env.engaged[:, None]
        np.testing.assert_allclose(tilt[near], env.u_teacher[near], atol=1e-12)
        on_estimate = env._mpc_on_estimate()
        np.testing.assert_allclose(tilt[far], on_estimate[far], atol=1e-12)
        near_seen, far_seen = near_seen + near.sum(), far_seen + far.sum()
        if env.tick % 45 == 5:   # the estimate's MPC is the mpc node's, where no constraint is active
            delay = env.actuation_delay_s
            for i in np.flatnonzero(env.engaged):
                mpc = PlateMpc(cfg)
                ref = env._ref_ahead(delay)[i]
                preview = np.stack([env._ref_ahead(delay + k * CONTROL_DT_S)[i] for k in range(1, cfg.horizon + 1)])
                u = mpc.solve(env.e[i] + ref[0], env.ve[i] + ref[1], preview[:, 0], preview[:, 1], preview[:, 2],
                              env.u_law[i], gain_ratio=env.estimator.k_g[i] / cfg.k_g,
                              offset_rad=env.estimator.offset[i] / cfg.k_g)
                if mpc.unconstrained:
                    np.testing.assert_allclose(on_estimate[i], u, atol=1e-9)
                    unconstrained += 1
        env.step()
    assert near_seen > 100 and far_seen > 20 and unconstrained > 5


def test_pid_alone_balances_the_nominal_plant():
    nominal = DomainRanges(gravity_scale=(1.0, 1.0), solid_ball_prob=0.0, latency_s=(0.0, 0.0),
                           detection_noise_m=(0.0005, 0.0005), frame_drop_prob=(0.0, 0.0), tilt_bias_rad=(0, 0),
                           gain_error=(1.0, 1.0), push_prob_per_s=0.0)
    env = PlateBatch(8, seed=1, ranges=nominal, duration_s=8.0)
    env.reset()
    while not env.finished:
        env.step()
    assert env.alive.all()
    assert np.nanmax(env.rmse_steady_m()) < 0.005


def test_episodes_are_reproducible_from_the_seed():
    runs = []
    for _ in range(2):
        env = PlateBatch(4, seed=7, duration_s=2.0)
        obs = env.reset()
        while not env.finished:
            obs = env.step(tilt=env.teacher_tilt())
        runs.append(obs)
    np.testing.assert_array_equal(runs[0], runs[1])


@pytest.mark.parametrize("knob", ["gravity_scale", "latency_s", "detection_noise_m"])
def test_training_domains_cover_the_benchmark_extremes(knob):
    from ball_balance.sim.config import DOMAINS

    low, high = getattr(DomainRanges(), knob)
    values = []
    for spec in DOMAINS.values():
        v = spec.get(knob)
        values += list(v) if isinstance(v, tuple) else [v] if v is not None else []
    assert low <= min(values) and high >= max(values)


def test_no_labels_between_a_push_and_the_frames_that_show_it():
    """push_visible: False from a push until `frames` camera frames after it can have reached
    the controller (the teacher answers the push at once, the student cannot see it yet)."""
    ranges = dataclasses.replace(DomainRanges(), push_prob_per_s=3.0)
    env = PlateBatch(8, seed=2, ranges=ranges, duration_s=3.0)
    env.reset()
    window_s = 2 / env.nom.camera_rate_hz + env.nom.vision_delay_s
    seen_hidden = seen_after = False
    while not env.finished:
        since = env.time_s - env.last_push_s
        visible = env.push_visible(2)
        np.testing.assert_array_equal(visible, since >= window_s - 1e-9)
        assert env.push_visible(0).all()
        seen_hidden |= bool((~visible).any())
        seen_after |= bool((visible & np.isfinite(env.last_push_s)).any())
        env.step()
    assert seen_hidden and seen_after


def test_the_plants_filter_looks_the_commands_up_with_the_episodes_delay_when_the_tracker_estimates_it():
    """With the tracker's online delay estimate the plant's filter takes the law's tilt in force
    latency + servo lag before each frame (what the estimate settles on); without it, the
    configured plate_cmd_delay_s."""
    from ball_balance.policy.env import tracker_config

    cfg = tracker_config()
    assert cfg.estimate_plate_cmd_delay   # the configuration the policy is trained for
    for estimate in (True, False):
        tracker = dataclasses.replace(cfg, estimate_plate_cmd_delay=estimate, plate_cmd_delay_s=0.01)
        env = PlateBatch(6, seed=4, duration_s=2.0, tracker_cfg=tracker)
        env.reset()
        want = env.latency + env.servo_lag if estimate else np.full(6, 0.01)
        np.testing.assert_allclose(env.plate_cmd_delay_s, want)
        while env.tick < 60:
            env.step(tilt=np.random.default_rng(env.tick).normal(0.0, 0.05, (6, 2)))
        t = env.time_s - 0.005
        got = env._known_tilt(t)
        for i in range(6):
            j = min(int(np.floor((t - want[i]) / CONTROL_DT_S + 1e-9)), env.tick - 1)
            np.testing.assert_array_equal(got[i], env.law_hist[i, :, j % env.hist_len])


def test_the_correction_fades_out_far_from_the_reference():
    """A correction faded out beyond twice a tiny distance never moves the plate: the plant runs
    as the PID alone, as the runtime's law does with the same weight."""
    runs = []
    for action, fade_m in ((None, 0.0), (np.ones((3, 2)), 1e-9)):
        env = PlateBatch(3, seed=5, duration_s=2.0, correction_fade_m=fade_m)
        obs = env.reset()
        while not env.finished:
            obs = env.step(action=action)
        runs.append(obs)
    np.testing.assert_array_equal(runs[0], runs[1])
