"""The online plant estimate (k g and a constant disturbance) from positions and plate tilts."""
import math

import numpy as np
from control_plant import K_G, DelayedPlant

from ball_balance.control.estimation import EstimatorConfig, PlantEstimator

DT = 0.02          # control tick: the tilt is recorded every tick
FRAME = 1.0 / 30   # camera: a ball position every frame


def _run(estimator, plant, duration_s, tilt_of_t, offset=(0.0, 0.0), noise_m=0.0, push_at=None, seed=0):
    rng = np.random.default_rng(seed)
    next_frame = 0.0
    for i in range(int(duration_s / DT)):
        t = i * DT
        u = tilt_of_t(t)
        estimator.add_tilt(t, u)
        if push_at is not None and abs(t - push_at) < DT / 2:
            plant.v += (0.15, 0.0)
        # the disturbance d enters as a constant tilt offset of -d / k_g
        plant.advance(np.asarray(u) - np.asarray(offset) / plant.k_g, DT)
        while next_frame <= t + DT + 1e-9:
            estimator.add_state(t + DT, plant.p + rng.normal(0.0, noise_m, 2))
            next_frame += FRAME


def _wobble(t):
    return (0.03 * math.sin(2.0 * t), 0.03 * math.cos(1.3 * t))


def test_gain_and_disturbance_are_found_from_a_moving_plate():
    k_true, d_true = 0.5 * K_G, np.array([0.05, -0.03])
    est = PlantEstimator(EstimatorConfig(adapt_gain=True, adapt_offset=True), K_G)
    _run(est, DelayedPlant(k_g=k_true), 25.0, _wobble, d_true, noise_m=0.0005)
    assert abs(est.k_g - k_true) < 0.1 * k_true
    np.testing.assert_allclose(est.offset, d_true, atol=0.015)


def test_a_still_plate_leaves_the_estimate_alone():
    est = PlantEstimator(EstimatorConfig(adapt_gain=True, adapt_offset=True), K_G)
    _run(est, DelayedPlant(), 5.0, lambda t: (0.0, 0.0), noise_m=0.0005)
    assert abs(est.k_g - K_G) < 0.02 * K_G
    assert np.all(np.abs(est.offset) < 0.01)


def test_estimate_stays_within_its_bounds_and_off_means_nominal():
    cfg = EstimatorConfig(adapt_gain=True, gain_max_ratio=1.5)
    est = PlantEstimator(cfg, K_G)
    _run(est, DelayedPlant(k_g=3.0 * K_G), 8.0, _wobble)
    assert est.k_g <= 1.5 * K_G + 1e-12
    off = PlantEstimator(EstimatorConfig(adapt_gain=False, adapt_offset=False), K_G)
    _run(off, DelayedPlant(k_g=0.5 * K_G), 4.0, _wobble)
    assert off.k_g == K_G and off.fits == 0


def test_a_push_does_not_throw_the_gain_off():
    k_true = 0.7 * K_G
    est = PlantEstimator(EstimatorConfig(adapt_gain=True, adapt_offset=True), K_G)
    _run(est, DelayedPlant(k_g=k_true), 25.0, _wobble, noise_m=0.0005, push_at=15.0)
    assert abs(est.k_g - k_true) < 0.15 * k_true
