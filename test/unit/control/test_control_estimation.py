"""The online plant estimate (k g and a constant disturbance) from positions and plate tilts."""
import math

import numpy as np
from control_plant import K_G, DelayedPlant

from ball_balance.control.estimation import (
    BatchPlantEstimator,
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


def _plates(b, n_steps, dt=0.02, rate_hz=30.0, drop_prob=0.0, push=(500, 1), seed=0):
    """Ball positions of `b` plates (x'' = -k u + d, each its own k and d, a push on one)
    under a wobbling tilt, with the tilt's exact double and single integrals: yields per
    camera frame (t, u over the ticks since the last frame, positions, P, V, arrived)."""
    rng = np.random.default_rng(seed)
    k_true = np.linspace(4.0, 9.0, b)
    d_true = rng.uniform(-0.1, 0.1, (b, 2))
    x, v = np.zeros((b, 2)), np.full((b, 2), 0.05)
    big_p, big_v = np.zeros((b, 2)), np.zeros((b, 2))
    next_frame, ticks = 0.0, []
    for n in range(n_steps):
        t = n * dt
        u = 0.03 * np.stack([np.sin(2 * np.pi * t / 3 + np.arange(b)), np.full(b, np.cos(2 * np.pi * t / 2.3))], 1)
        ticks.append((t, u))
        if t >= next_frame - 1e-9:
            next_frame += 1 / rate_hz
            yield t, ticks, x + rng.normal(0, 0.001, (b, 2)), big_p.copy(), big_v.copy(), rng.random(b) >= drop_prob
            ticks = []
        if n == push[0]:
            v[push[1]] += (0.15, 0.0)
        a = -k_true[:, None] * u + d_true
        x, v = x + v * dt + 0.5 * a * dt * dt, v + a * dt
        big_p, big_v = big_p + big_v * dt + 0.5 * u * dt * dt, big_v + u * dt


def _estimates(est):
    return np.concatenate([est.k_g, est.offset.ravel(), est.fits, est.skipped, est.restarts])


def test_a_batch_of_plates_is_each_plate_estimated_alone():
    """Plates with their own gains, disturbances, dropped frames and a push estimate in a batch
    as each does alone (a batch of one), window restarts and counters included; a plate given
    its d by the tracker keeps it."""
    b, k_nominal = 4, 5.886
    cfg = EstimatorConfig()
    capacity = int(np.ceil(cfg.window_s * 30)) + 8
    batch = BatchPlantEstimator(b, cfg, k_nominal, capacity)
    alone = [BatchPlantEstimator(1, cfg, k_nominal, capacity) for _ in range(b)]
    level = np.array([[np.nan, np.nan], [np.nan, np.nan], [np.nan, np.nan], [0.01, -0.02]])
    batch.take_level_offset(level)
    alone[3].take_level_offset(level[3:])
    for t, _, z, big_p, big_v, arrived in _plates(b, 900, drop_prob=0.1):
        batch.add_state(np.full(b, t), z, big_p, big_v, arrived)
        for i in range(b):
            alone[i].add_state(np.full(1, t), z[i:i + 1], big_p[i:i + 1], big_v[i:i + 1], arrived[i:i + 1])
    assert batch.restarts[1] + batch.skipped[1] > 0 and batch.fits.min() > 300
    np.testing.assert_allclose(_estimates(batch), np.concatenate(
        [np.concatenate([e.k_g for e in alone]), np.concatenate([e.offset.ravel() for e in alone]),
         *[np.concatenate([getattr(e, c) for e in alone]) for c in ("fits", "skipped", "restarts")]]), rtol=1e-9)
    np.testing.assert_allclose(batch.k_g, np.linspace(4.0, 9.0, b), rtol=0.05)
    np.testing.assert_allclose(batch.offset[3], k_nominal * np.sin(level[3]))


def test_the_plant_estimator_is_the_batch_of_one_integrating_its_own_tilts():
    """PlantEstimator integrates the tilt from its history itself (restarting the integrals
    with a window after a gap); the batch, given the tilt's exact integrals, estimates the same."""
    cfg = EstimatorConfig()
    batch = BatchPlantEstimator(1, cfg, K_G, int(np.ceil(cfg.window_s * 30)) + 8)
    single = PlantEstimator(cfg, K_G)
    for t, ticks, z, big_p, big_v, _ in _plates(1, 900, push=(500, 0)):
        for t_tick, u in ticks:
            single.add_tilt(t_tick, u[0])
        single.add_state(t, z[0])
        batch.add_state(np.full(1, t), z, big_p, big_v, np.ones(1, bool))
    assert single.restarts + single.skipped > 0 and single.fits > 300
    assert (single.fits, single.skipped, single.restarts) == (batch.fits[0], batch.skipped[0], batch.restarts[0])
    np.testing.assert_allclose(single.k_g, batch.k_g[0], rtol=1e-9)
    np.testing.assert_allclose(single.offset, batch.offset[0], atol=1e-12)


def test_a_fast_camera_grows_the_ring_and_loses_no_sample():
    """A stream faster than the ring was sized for: the ring grows, and the estimate is the
    one a ring large enough from the start gives."""
    cfg = EstimatorConfig()
    small = BatchPlantEstimator(2, cfg, K_G, 16)
    large = BatchPlantEstimator(2, cfg, K_G, int(np.ceil(cfg.window_s * 50)) + 8)
    for t, _, z, big_p, big_v, arrived in _plates(2, 400, dt=0.01, rate_hz=50.0, drop_prob=0.1):
        for est in (small, large):
            est.add_state(np.full(2, t), z, big_p, big_v, arrived)
    assert small.cap > 150 and large.cap == int(np.ceil(cfg.window_s * 50)) + 8
    np.testing.assert_allclose(_estimates(small), _estimates(large), rtol=1e-9)


def test_reset_forgets_the_window_and_bad_samples_are_ignored():
    est = PlantEstimator(EstimatorConfig(), K_G)
    _run(est, DelayedPlant(k_g=0.5 * K_G), 6.0, _wobble, noise_m=0.0005)
    k_g, offset, fits = est.k_g, est.offset, est.fits
    assert fits > 0 and k_g < 0.9 * K_G
    for stamp, pos in ((math.nan, (0.0, 0.0)), (7.0, (math.inf, 0.0)), (1.0, (0.0, 0.0)), (6.0, (0.0, 0.0))):
        est.add_state(stamp, pos)   # not finite, older than the last state, the same stamp
    assert est.batch.last_t[0] == 6.0 and est.fits == fits
    est.take_level_offset((math.nan, 0.0))
    np.testing.assert_array_equal(est.offset, offset)
    est.reset()
    assert (est.k_g, est.fits) == (k_g, fits)
    np.testing.assert_array_equal(est.offset, offset)
    _run(est, DelayedPlant(k_g=0.5 * K_G), 1.0, _wobble, noise_m=0.0005)   # its clock from 0 again
    assert est.fits == fits   # under half a window since the reset: no fit yet


def test_a_given_disturbance_is_kept_while_the_gain_is_estimated():
    k_true, d_true = 0.5 * K_G, np.array([0.05, -0.03])
    est = PlantEstimator(EstimatorConfig(), K_G)
    level = np.arcsin(d_true / K_G)
    est.take_level_offset(level)
    given = est.offset
    _run(est, DelayedPlant(k_g=k_true), 25.0, _wobble, d_true, noise_m=0.0005)
    np.testing.assert_array_equal(est.offset, given)
    assert abs(est.k_g - k_true) < 0.1 * k_true


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
