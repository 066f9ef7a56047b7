"""The vectorised training plant agrees with the controllers it stands in for."""
import numpy as np
import pytest

from ball_balance.benchmark.episode import controller_values
from ball_balance.control import config as control_config
from ball_balance.control.pid import AxisPid
from ball_balance.policy.env import BatchPid, DomainRanges, PlateBatch


def test_batch_pid_is_the_axis_pid():
    values = controller_values("pid", "stationary")
    gains, k_g = control_config.pid_gains(values), control_config.k_g(values)
    rng = np.random.default_rng(3)
    batch = BatchPid((5, 2), values, k_g, gains.u_max_rad)
    axes = [[AxisPid(gains, k_g) for _ in range(2)] for _ in range(5)]
    for _ in range(300):
        e, ve, a = rng.normal(0, 0.03, (5, 2)), rng.normal(0, 0.1, (5, 2)), rng.normal(0, 0.2, (5, 2))
        got = batch.step(e, ve, a, 0.02)
        want = np.array([[axes[i][j].step(e[i, j], ve[i, j], a[i, j], 0.02) for j in range(2)] for i in range(5)])
        np.testing.assert_allclose(got, want, atol=1e-12)


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
