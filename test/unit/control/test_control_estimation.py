"""The online plant estimate (k g and a constant disturbance) from positions and plate tilts."""
import math

import numpy as np
from control_plant import K_G, DelayedPlant

from ball_balance.control.estimation import (
    EstimatorConfig,
    PlantEstimator,
    level_offset_deg,
    level_offset_summary,
    plant_statistics,
)

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


def test_half_gravity_is_found_while_a_pid_tracks_a_circle_in_closed_loop():
    """The case the PID's feed-forward depends on: a circle on a half-gravity plant, the tilt
    from the PID with its defaults (feed-forward from the estimate) reacting to noisy positions
    and velocities, so the noise reaches the tilt through the loop. With the PID's time
    constant (the schema's adapt_time_constant_s for the PID) the estimate must move steadily
    to the true k g, not settle at a value biased by that feedback."""
    from ball_balance.control import config as control_config
    from ball_balance.control.pid import PidGains, PlatePid
    from ball_balance.control.references import Circle
    from controller_manager_py.parameters import validate

    cfg = control_config.estimator_config(validate(control_config.PID_SCHEMA, {}))
    k_true = 0.5 * K_G
    rng = np.random.default_rng(3)
    est = PlantEstimator(cfg, K_G)
    pid = PlatePid(PidGains(), K_G)
    plant = DelayedPlant(x0=(0.1, 0.0), v0=(0.0, 2 * math.pi * 0.1 / 10.0), delay_s=0.04, k_g=k_true)
    circle = Circle(0.1, 10.0)
    measured = plant.p.copy()
    ratio_at = {}
    for i in range(int(16.0 / DT)):
        t = i * DT
        ref = circle.sample(t)
        scaled = type(ref)(ref.p, ref.v, np.asarray(ref.a) * (K_G / est.k_g))   # feed-forward -a / k_g
        u = pid.step(measured, plant.v + rng.normal(0.0, 0.005, 2), scaled, DT)
        est.add_tilt(t, u)
        plant.advance(u, DT)
        if i % 2 == 0:   # a new position every other tick (25 Hz)
            measured = plant.p + rng.normal(0.0, 0.0005, 2)
            est.add_state(t + DT, measured)
        ratio_at[round(t + DT, 2)] = est.k_g / K_G
    assert ratio_at[4.0] < 0.85                 # well on its way after 4 s (5 s constant: 0.91)
    assert ratio_at[8.0] < 0.65
    assert abs(ratio_at[16.0] - 0.5) < 0.04     # and there, not biased by the noise in the loop
    assert min(ratio_at.values()) > 0.45        # without overshooting


def test_the_disturbance_reads_as_the_plate_level_offset_that_causes_it():
    # a plate mounted 2 degrees off level (or a force m g sin 2deg on the ball) is d = k g sin(2 deg)
    d = K_G * np.sin(np.radians([2.0, -1.0]))
    np.testing.assert_allclose(level_offset_deg(d, K_G), [2.0, -1.0], atol=1e-12)
    assert level_offset_deg([10.0 * K_G, 0.0], K_G)[0] == 90.0   # clipped, never NaN
    est = PlantEstimator(EstimatorConfig(adapt_gain=True, adapt_offset=True), K_G)
    est.offset = d
    names = dict(plant_statistics(lambda: est))
    assert list(names) == ["disturbance_tilt_x_deg", "disturbance_tilt_y_deg", "plant_gain_ratio"]
    assert math.isclose(names["disturbance_tilt_x_deg"](), 2.0) and math.isclose(names["plant_gain_ratio"](), 1.0)


def test_the_level_offset_in_words_says_how_far_and_which_way_the_ball_is_pushed():
    text = level_offset_summary(0.0, 2.0)   # e.g. /sim/set_ball_force 2 deg towards 90 deg
    assert "2.00 deg off level" in text and "towards 90 deg" in text and "y +2.00" in text
    assert "towards 225 deg" in level_offset_summary(-1.0, -1.0)
    assert "0.00 deg off level" in level_offset_summary(0.0, 0.0)
    assert "no estimate" in level_offset_summary(math.nan, 0.0)
