"""The plant's batched filter with the tilt's lever (vision/kalman.py BallKalman.step's `lever`)
and a push (the maneuver hold's constant-velocity filter): the same estimates as BallKalman
frame by frame."""
import numpy as np

from ball_balance.policy.batch_kalman import BatchBallKalman
from ball_balance.vision.config import TrackerConfig
from ball_balance.vision.kalman import BallKalman, KalmanConfig


def test_batch_kalman_with_the_tilt_lever_is_the_trackers_filter():
    tracker_cfg = TrackerConfig.from_values({"disturbance_time_constant_s": 0.0})   # as the training plant's
    cfg = KalmanConfig.from_tracker(tracker_cfg)
    b, dt, k_g, c = 4, 1 / 30, 5.886, tracker_cfg.tilt_lever_m
    batch = BatchBallKalman(b, cfg)
    single = [BallKalman(cfg) for _ in range(b)]
    rng = np.random.default_rng(3)
    x, v = rng.normal(0, 0.03, (b, 2)), np.zeros((b, 2))
    worst = 0.0
    for n in range(200):
        t = n * dt
        u = 0.06 * np.sin(2 * np.pi * t / np.array([1.0, 1.5, 2.0, 0.8]))[:, None] * np.array([1.0, -0.5])
        accel, lever = -k_g * np.sin(u), c * u
        x, v = x + v * dt + 0.5 * accel * dt * dt, v + accel * dt
        if n == 100:
            v[1] += 0.15                                    # a push
        # detections a little better than the configured 1 mm: the running consistency stays well
        # below MODEL_AGREED_NIS before the push, so the push surely takes the hold under test
        z = x + lever + rng.normal(0, 0.0007, (b, 2))
        det = rng.random(b) >= 0.1
        pos, vel, valid = batch.step(t, z, det, accel, lever)
        for i in np.flatnonzero(det):
            est = single[i].step(t, tuple(z[i]), tuple(accel[i]), tuple(lever[i]))
            assert valid[i] == est.valid
            got, want = np.concatenate([pos[i], vel[i]]), np.array([est.x, est.y, est.vx, est.vy])
            np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-9, err_msg=f"frame {n} ball {i}")
            worst = max(worst, float(np.max(np.abs(got - want))))
    assert worst < 1e-9
    assert np.isfinite(batch.hold_until[1]) and single[1].fast is not None   # the push took the maneuver hold
