"""Latency compensation: the delayed plant is controlled better with forward prediction."""
import numpy as np
import pytest
from control_plant import K_G, DelayedPlant

from ball_balance.control.mpc import MpcConfig, PlateMpc, preview
from ball_balance.control.pid import PidGains, PlatePid
from ball_balance.control.prediction import TiltHistory, predict
from ball_balance.control.references import Circle


def test_prediction_is_exact_for_piecewise_constant_tilts():
    hist = TiltHistory()
    hist.record(0.0, 0.1, 0.0)
    hist.record(0.05, -0.1, 0.02)
    plant = DelayedPlant(dt_s=0.0005)
    plant.advance((0.1, 0.0), 0.05)
    plant.advance((-0.1, 0.02), 0.05)
    p, v = predict(np.zeros(2), np.zeros(2), 0.0, 0.1, hist, K_G)
    np.testing.assert_allclose(p, plant.p, atol=1e-9)
    np.testing.assert_allclose(v, plant.v, atol=1e-9)


def _tracking_rmse(controller, compensate, delay_s=0.1, dt=0.02, seconds=12.0):
    """Plant with a measurement delay (state seen delay_s late) and actuation delay 0.02 s."""
    plant = DelayedPlant(x0=(0.05, 0.0), delay_s=0.02)
    ref = Circle(0.08, 8.0)
    hist = TiltHistory()
    past = []
    u = np.zeros(2)
    errors = []
    lag = int(round(delay_s / dt))
    for i in range(int(seconds / dt)):
        t = i * dt
        past.append((t, plant.p.copy(), plant.v.copy()))
        t_meas, p, v = past[max(0, len(past) - 1 - lag)]
        if compensate:
            p, v = predict(p, v, t_meas, t + 0.02, hist, K_G, actuation_delay_s=0.02)
        if controller == "pid":
            u = np.array(PID.step(p, v, ref.sample(t), dt))
        else:
            pr, vr, ar = preview(ref, t, dt, 25)
            u = np.array(MPC.solve(p, v, pr, vr, ar, u))
        hist.record(t, *u)
        plant.advance(u, dt)
        if not np.all(np.abs(plant.p) < 0.3):
            return np.inf
        if t > 4.0:
            errors.append(np.linalg.norm(plant.p - ref.sample(t + dt).p))
    return float(np.sqrt(np.mean(np.square(errors))))


def test_tilt_history_lookups_are_the_scan_they_replace():
    rng = np.random.default_rng(3)
    history = TiltHistory(max_len=64)
    times = np.cumsum(rng.choice([0.0, 0.01, 0.02], 100))   # repeated instants too
    recorded = []
    for t in times:
        u_x, u_y = rng.normal(size=2)
        history.record(float(t), float(u_x), float(u_y))
        recorded.append((float(t), float(u_x), float(u_y)))
    entries = recorded[-64:]   # what a 64-long history keeps

    def scan_at(t):
        u = (0.0, 0.0)
        for t_i, ux, uy in entries:
            if t_i > t:
                break
            u = (ux, uy)
        return u

    for t in np.concatenate([times, times + 0.005, times - 0.005, [-1.0, 99.0]]):
        t1 = float(t) + 0.05
        issued, tilts = history.acting(float(t), t1)
        inside = [e for e in entries if float(t) < e[0] < t1]
        assert list(issued[1:]) == [t_i for t_i, _, _ in inside]
        assert tuple(tilts[0]) == scan_at(float(t)) and [tuple(u) for u in tilts[1:]] == [e[1:] for e in inside]


def test_tilt_history_starts_again_when_the_clock_goes_back():
    history = TiltHistory()
    history.record(10.0, 0.1, 0.2)
    history.record(10.1, 0.3, 0.4)
    history.record(0.5, -0.1, 0.0)          # e.g. a simulation restarted under /clock

    def in_force(t):
        return tuple(history.acting(t, t + 1e-3)[1][0])
    assert in_force(0.6) == (-0.1, 0.0)
    assert in_force(10.05) == (-0.1, 0.0) and in_force(0.4) == (0.0, 0.0)


@pytest.mark.parametrize("controller", ["pid", "mpc"])
def test_latency_compensation_improves_a_delayed_plant(controller):
    global PID, MPC
    results = {}
    for compensate in (False, True):
        PID = PlatePid(PidGains(), K_G)
        MPC = PlateMpc(MpcConfig(k_g=K_G))
        results[compensate] = _tracking_rmse(controller, compensate)
    assert results[True] < 0.5 * results[False], results
    assert results[True] < 0.005, results


def test_delay_estimator_finds_the_command_to_plate_delay():
    from ball_balance.control.prediction import DelayEstimator

    period = 0.02
    est = DelayEstimator(initial_s=0.03, period_s=period)
    rng = np.random.default_rng(0)
    commands = np.cumsum(rng.normal(0, 0.01, (600, 2)), axis=0)
    lag = 6  # 0.12 s
    for i in range(len(commands)):
        measured = commands[i - lag] if i >= lag else np.zeros(2)
        est.add(commands[i], measured)
    assert est.estimate_s == pytest.approx(0.12, abs=0.01)


def test_delay_estimator_keeps_its_value_without_excitation():
    from ball_balance.control.prediction import DelayEstimator

    est = DelayEstimator(initial_s=0.05, period_s=0.02)
    for _ in range(500):
        est.add((0.0, 0.0), (0.0, 0.0))
    assert est.estimate_s == 0.05


def test_delay_estimator_over_a_batch_is_each_plate_estimated_alone():
    """A delay per plate of a batch, bit for bit what each plate's estimator gives alone, a
    plate that stops moving (no update) included."""
    from ball_balance.control.prediction import DelayEstimator

    b, lags = 4, [0, 3, 7, 12]
    single = [DelayEstimator(0.03, 0.02) for _ in range(b)]
    batch = DelayEstimator(0.03, 0.02, batch_shape=(b,))
    rng = np.random.default_rng(0)
    cmds = []
    for n in range(600):
        w = np.arange(1, b + 1) * n * 0.02
        u = 0.02 * np.stack([np.sin(0.7 * w), np.cos(0.5 * w)], 1)
        if n > 400:
            u[0] = 0.0
        cmds.append(u)
        meas = np.stack([cmds[max(0, n - lags[i])][i] for i in range(b)]) + rng.normal(0, 1e-4, (b, 2))
        got = batch.add(u, meas)
        assert np.array_equal(got, [single[i].add(u[i], meas[i]) for i in range(b)])
    assert np.array_equal(batch.converged, [e.converged for e in single])
    np.testing.assert_allclose(got[1:], np.array(lags[1:]) * 0.02, atol=0.005)
    assert isinstance(single[0].estimate_s, float)   # one plate: a number, as the pipeline uses it


def _lagged_commands(lag: int, n: int = 400):
    rng = np.random.default_rng(1)
    commands = np.cumsum(rng.normal(0, 0.01, (n, 2)), axis=0)
    measured = [commands[i - lag] if i >= lag else np.zeros(2) for i in range(n)]
    return commands, measured


def test_delay_estimator_replaces_a_wrong_start_value_within_a_second():
    # 0.2 s delay, start value 0.03 s: the first alignment (after min_window_s + the longest lag)
    # takes the measured delay, it does not wait 3.3 s for a full window and creep toward it
    from ball_balance.control.prediction import DelayEstimator

    period = 0.02
    est = DelayEstimator(initial_s=0.03, period_s=period, min_window_s=0.6)
    commands, measured = _lagged_commands(lag=10)
    for i in range(50):   # 1.0 s
        est.add(commands[i], measured[i])
    assert est.converged
    assert est.estimate_s == pytest.approx(0.2, abs=0.01)


def test_pipeline_takes_the_delay_estimate_window_from_the_schema():
    from ball_balance.control import config as control_config
    from controller_manager_py.parameters import validate
    values = validate(control_config.PID_SCHEMA)
    assert values["actuation_delay_min_window_s"] == 0.6
    values = validate(control_config.PID_SCHEMA, {"actuation_delay_min_window_s": 1.5})
    cfg = control_config.pipeline_config(values, "pid")
    assert cfg.delay_min_window_s == 1.5
