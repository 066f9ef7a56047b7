"""The disturbance observer (control/disturbance.py): a step converges, a clean plant reads no
bias, a push is not taken for a disturbance."""
import numpy as np

from ball_balance.control.disturbance import DisturbanceObserver

FRAME = 1.0 / 30


def _observe(disturbance_of_t, duration_s=6.0, noise_m=0.001, push_at_s=None, push_m_s=(0.3, 0.0), seed=0,
             settle_s=0.3):
    """A ball under a PD loop (its acceleration -9 p - 4 v is the known input) and the
    disturbance disturbance_of_t(t); the observer sees noisy positions at 30 Hz. Returns the
    times and the estimates (n, 2)."""
    observer = DisturbanceObserver(position_noise_m=0.002, accel_noise_m_s2=0.01, settle_time_s=settle_s,
                                   max_disturbance_m_s2=0.6)
    rng = np.random.default_rng(seed)
    p, v = np.zeros(2), np.zeros(2)
    times, estimates = [], []
    for k in range(int(duration_s / FRAME)):
        t = k * FRAME
        if push_at_s is not None and abs(t - push_at_s) < FRAME / 2:
            v = v + np.asarray(push_m_s)
        a_in = -9.0 * p - 4.0 * v
        a = a_in + np.asarray(disturbance_of_t(t))
        p = p + v * FRAME + 0.5 * a * FRAME ** 2
        v = v + a * FRAME
        times.append(t)
        estimates.append(observer.step(t, p + rng.normal(0.0, noise_m, 2), 0.5 * a_in * FRAME ** 2, a_in * FRAME))
    return np.array(times), np.array(estimates), observer


def test_a_step_disturbance_is_found_within_a_second():
    step = np.array([0.31, -0.15])            # 3 and 1.5 degrees of level offset at 0.6 g
    t, d, _ = _observe(lambda t: step if t >= 1.0 else np.zeros(2))
    after = t >= 2.0
    assert np.all(np.abs(d[after] - step) < 0.1 * np.abs(step).max())
    late = t >= 4.0
    np.testing.assert_allclose(d[late].mean(axis=0), step, atol=0.01)


def test_a_clean_plant_reads_no_bias():
    t, d, _ = _observe(lambda t: np.zeros(2), duration_s=10.0)
    settled = t >= 2.0
    assert np.all(np.abs(d[settled].mean(axis=0)) < 0.003)   # 0.03 degrees
    assert np.all(d[settled].std(axis=0) < 0.02)


def test_a_disturbance_that_ends_leaves_no_tail():
    t, d, _ = _observe(lambda t: np.array([0.3, 0.0]) if 1.0 <= t < 4.0 else np.zeros(2), duration_s=7.0)
    assert np.all(np.abs(d[t >= 5.0, 0]) < 0.03)


def test_a_push_is_not_taken_for_a_disturbance():
    t, d, observer = _observe(lambda t: np.zeros(2), duration_s=5.0, push_at_s=2.0)
    assert observer.pushes >= 1
    assert np.all(np.abs(d[t >= 2.0]) < 0.06)   # a 0.3 m/s push reads as under 0.6 degrees


def test_a_lost_track_keeps_the_disturbance():
    _, _, observer = _observe(lambda t: np.array([0.2, 0.0]), duration_s=4.0)
    before = observer.d
    observer.reset()
    observer.step(10.0, (0.05, 0.0), (0.0, 0.0), (0.0, 0.0))
    np.testing.assert_allclose(observer.d, before)


def test_a_non_finite_position_changes_nothing():
    observer = DisturbanceObserver(0.002, 0.01, 0.3, 0.6)
    observer.step(0.0, (0.0, 0.0), (0.0, 0.0), (0.0, 0.0))
    state = observer.x.copy()
    observer.step(0.1, (float("nan"), 0.0), (0.0, 0.0), (0.0, 0.0))
    np.testing.assert_array_equal(observer.x, state)
