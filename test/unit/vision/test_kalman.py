"""Constant-velocity Kalman filter: convergence, variable dt, gating, coasting and reset."""
import numpy as np
import pytest
from filterpy.common import Q_discrete_white_noise

from ball_balance.vision.kalman import BallKalman


def test_process_noise_matches_filterpys_white_noise_acceleration_model():
    kf = BallKalman(accel_noise_m_s2=2.0)
    kf.step(0.0, (0.0, 0.0))
    kf.step(0.04, (0.0, 0.0))
    Q_axis = Q_discrete_white_noise(dim=2, dt=0.04, var=4.0)            # [x, vx] of one axis
    np.testing.assert_allclose(kf.kf.Q[np.ix_([0, 2], [0, 2])], Q_axis, atol=1e-12)
    np.testing.assert_allclose(kf.kf.Q[np.ix_([1, 3], [1, 3])], Q_axis, atol=1e-12)


def test_velocity_converges_with_jittered_frame_times():
    rng = np.random.default_rng(3)
    kf = BallKalman(meas_noise_m=0.001, accel_noise_m_s2=0.3)
    t, v = 0.0, np.array([0.2, -0.1])
    for _ in range(90):
        t += rng.uniform(0.02, 0.045)
        est = kf.step(t, tuple(v * t + rng.normal(0, 0.001, 2)))
    assert est.fresh and est.valid
    assert est.vx == pytest.approx(0.2, abs=0.02) and est.vy == pytest.approx(-0.1, abs=0.02)
    assert est.x == pytest.approx(0.2 * t, abs=0.002)


def test_coasts_for_max_frames_then_resets_and_restarts_on_next_detection():
    kf = BallKalman(max_coast_frames=3)
    for i in range(10):
        kf.step(i / 30, (0.1 * i / 30, 0.0))
    coast = [kf.step((10 + i) / 30, None) for i in range(4)]
    assert [(e.fresh, e.valid) for e in coast] == [(False, True)] * 3 + [(False, False)]
    assert coast[1].x > coast[0].x                                     # keeps moving while coasting
    assert coast[3].vx == 0.0 and kf.reset_count == 1
    restart = kf.step(14 / 30, (-0.05, 0.02))
    assert restart.fresh and restart.valid and restart.x == -0.05 and restart.vx == 0.0


def test_outlier_is_gated_and_counted():
    kf = BallKalman(meas_noise_m=0.001, gate_sigma=6.0)
    for i in range(20):
        kf.step(i / 30, (0.0, 0.0))
    est = kf.step(20 / 30, (0.15, 0.0))
    assert est.gated and not est.fresh and est.valid and abs(est.x) < 0.001
    assert kf.gated_count == 1


def test_long_gap_resets_the_track():
    kf = BallKalman(max_dt_s=0.5)
    kf.step(0.0, (0.1, 0.1))
    kf.step(0.03, (0.1, 0.1))
    est = kf.step(1.0, (-0.1, 0.0))
    assert est.valid and est.x == -0.1 and kf.reset_count == 1


def test_known_acceleration_is_used_in_the_prediction():
    with_accel, without = BallKalman(accel_noise_m_s2=0.5), BallKalman(accel_noise_m_s2=0.5)
    a = 1.5
    for i in range(30):
        t = i / 30
        z = (0.5 * a * t * t, 0.0)
        with_accel.step(t, z, accel=(a, 0.0))
        without.step(t, z)
    assert abs(with_accel.kf.x[2] - a * 29 / 30) < abs(without.kf.x[2] - a * 29 / 30)
    assert with_accel.kf.x[2] == pytest.approx(a * 29 / 30, abs=0.01)


def test_no_detection_before_any_track_is_invalid_zero():
    est = BallKalman().step(0.0, None)
    assert not est.valid and not est.fresh and (est.x, est.y, est.vx, est.vy) == (0, 0, 0, 0)
