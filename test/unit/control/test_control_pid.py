import numpy as np
import pytest
from control_plant import K_G, DelayedPlant

from ball_balance.control.pid import Pid, PidGains, PlatePid
from ball_balance.control.references import Circle, Stationary


def test_ball_right_of_reference_gets_positive_tilt_that_drives_it_toward_minus_x():
    pid = PlatePid(PidGains(), K_G)
    u = pid.step(np.array([0.05, -0.05]), np.zeros(2), Stationary().sample(0.0), 0.02)
    assert u[0] > 0 and u[1] < 0
    plant = DelayedPlant(x0=(0.05, -0.05))
    plant.advance(u, 0.1)
    assert plant.v[0] < 0 and plant.v[1] > 0


def test_output_is_clipped():
    pid = Pid(PidGains(u_max_rad=0.1), K_G)
    assert pid.step(10.0, 10.0, 0.0, 0.02) == 0.1
    assert pid.step(-10.0, -10.0, 0.0, 0.02) == -0.1


def test_integral_does_not_wind_up_while_saturated():
    gains = PidGains(ki=2.0, u_max_rad=0.1, i_limit_rad=0.05)
    pid = Pid(gains, K_G)
    for _ in range(500):  # 10 s pinned at saturation
        pid.step(0.2, 0.0, 0.0, 0.02)
    assert abs(gains.ki * pid.integral) <= 0.05 + 1e-12
    # as soon as the error reverses, the output leaves saturation immediately
    assert pid.step(-0.02, 0.0, 0.0, 0.02) < 0.1


def test_derivative_filter_smooths_the_velocity_and_reset_forgets_it():
    g = PidGains(kp=0.0, ki=0.0, kd=1.0, derivative_filter_s=0.06)
    pid = Pid(g, K_G)
    assert pid.step(0.0, 0.01, 0.0, 0.02) == pytest.approx(0.01)   # the first sample passes
    # a velocity step: a quarter (0.02 / (0.06 + 0.02)) of it at once, then first-order
    assert pid.step(0.0, 0.05, 0.0, 0.02) == pytest.approx(0.01 + 0.25 * 0.04)
    for _ in range(50):
        u = pid.step(0.0, 0.05, 0.0, 0.02)
    assert u == pytest.approx(0.05, abs=1e-6)
    # alternating noise is cut to a fraction of what the unfiltered D passes
    noisy = [pid.step(0.0, 0.05 + (0.02 if k % 2 else -0.02), 0.0, 0.02) - 0.05 for k in range(20)]
    assert max(abs(v) for v in noisy[5:]) < 0.3 * 0.02
    pid.reset()
    assert pid.step(0.0, -0.03, 0.0, 0.02) == pytest.approx(-0.03)


def test_gain_scale_scales_the_feedback_but_not_the_feed_forward():
    g = PidGains(kp=2.0, ki=0.0, kd=0.5, derivative_filter_s=0.0)
    full = Pid(g, K_G).step(0.01, 0.02, 0.0, 0.02)
    assert Pid(g, K_G).step(0.01, 0.02, 0.0, 0.02, gain_scale=0.5) == pytest.approx(0.5 * full)
    ff = Pid(g, K_G).step(0.0, 0.0, -0.3, 0.02, gain_scale=0.5)
    assert ff == pytest.approx(0.3 / K_G)


def test_without_an_integral_gain_nothing_is_integrated():
    pid = Pid(PidGains(ki=0.0), K_G)
    for _ in range(100):
        pid.step(0.01, 0.0, 0.0, 0.02)
    assert np.all(pid.integral == 0.0)


def test_derivative_uses_measured_velocity():
    g = PidGains(kp=0.0, ki=0.0, kd=1.0, derivative_filter_s=0.0)
    assert Pid(g, K_G).step(0.0, 0.3, 0.0, 0.02) == 0.15  # clipped at default u_max
    assert Pid(g, K_G).step(0.0, 0.1, 0.0, 0.02) == 0.1


def test_closed_loop_settles_from_off_centre_release():
    pid = PlatePid(PidGains(), K_G)
    plant = DelayedPlant(x0=(0.1, -0.08), delay_s=0.04)
    ref = Stationary().sample(0.0)
    for _ in range(400):  # 8 s at 50 Hz
        u = pid.step(plant.p, plant.v, ref, 0.02)
        plant.advance(u, 0.02)
    assert np.linalg.norm(plant.p) < 0.002


def test_saturation_by_a_big_error_never_charges_the_integral_against_it():
    """A large error saturates through P and D: the integral must not swing to its opposite
    clamp (the bug left the ball 10-15 mm off target for seconds after a big move)."""
    gains = PidGains(kp=2.0, ki=0.4, kd=0.75, u_max_rad=0.15, i_limit_rad=0.03, antiwindup_time_s=0.2,
                     derivative_filter_s=0.0)
    pid = Pid(gains, K_G)
    pid.integral = 0.01                      # a little integral toward +u from before the move
    for _ in range(100):                     # saturated by a fast approach (D)
        assert pid.step(0.01, 0.3, 0.0, 0.02) == 0.15
        assert pid.integral >= 0.0           # unwound toward zero, never past it
    assert pid.integral == 0.0
    pid.integral = -0.05                     # an integral opposing the saturation is not touched
    pid.step(0.01, 0.5, 0.0, 0.02)
    assert pid.integral == -0.05             # conditional integration: e > 0 pushes out, no growth


def test_after_a_saturating_release_the_ball_settles_close_to_the_target():
    pid = PlatePid(PidGains(), K_G)
    plant = DelayedPlant(x0=(0.12, -0.1), v0=(0.2, -0.2), delay_s=0.04)
    ref = Stationary().sample(0.0)
    saturated = 0
    for _ in range(250):                     # 5 s at 50 Hz
        u = pid.step(plant.p, plant.v, ref, 0.02)
        saturated += max(abs(u[0]), abs(u[1])) >= 0.15
        plant.advance(u, 0.02)
    assert saturated > 5                     # the case under test: the output did saturate
    assert np.linalg.norm(plant.p) < 0.003


def _random_inputs(rng, shape, ticks):
    """Errors small and large enough to saturate, with a feedback scale per plate."""
    for k in range(ticks):
        scale = 0.3 if k % 40 < 10 else 0.015
        yield (rng.normal(0, scale, shape), rng.normal(0, 0.05, shape), rng.normal(0, 0.2, shape),
               rng.uniform(0.5, 1.0, shape[:-1] + (1,)), rng.normal(0, 0.01, shape))


@pytest.mark.parametrize("gains", [PidGains(), PidGains(derivative_filter_s=0.0, ki=2.0),
                                   PidGains(ki=0.4, antiwindup_time_s=0.0)])
def test_a_batch_of_plates_is_each_plate_stepped_alone(gains):
    """The law over a (3, 2) batch gives, bit for bit, what three plates' laws give alone and
    what six single axes give: every element is an independent axis."""
    batch = Pid(gains, K_G, (3, 2))
    plates = [Pid(gains, K_G, (2,)) for _ in range(3)]
    axes = [[Pid(gains, K_G) for _ in range(2)] for _ in range(3)]
    saturated = 0
    for e, ve, a, scale, bias in _random_inputs(np.random.default_rng(3), (3, 2), 300):
        u = batch.step(e, ve, a, 0.02, gain_scale=scale, u_bias_rad=bias)
        alone = np.array([plates[i].step(e[i], ve[i], a[i], 0.02, float(scale[i, 0]), bias[i]) for i in range(3)])
        single = np.array([[axes[i][j].step(e[i, j], ve[i, j], a[i, j], 0.02, float(scale[i, 0]), bias[i, j])
                            for j in range(2)] for i in range(3)])
        assert np.array_equal(u, alone) and np.array_equal(u, single)
        assert np.array_equal(batch.integral, [p.integral for p in plates])
        saturated += int(np.count_nonzero(batch.saturated))
    assert saturated > 50                    # the anti-windup paths were exercised


def test_plate_pid_steps_the_law_on_the_error_to_the_reference():
    ref = Circle(0.1, 8.0).sample(1.0)
    plate, law = PlatePid(PidGains(), K_G), Pid(PidGains(), K_G, (2,))
    pos, vel, bias = np.array([0.05, 0.02]), np.array([0.1, -0.1]), np.array([0.002, -0.001])
    for _ in range(3):
        u = plate.step(pos, vel, ref, 0.02, 0.8, bias)
        assert u == tuple(law.step(pos - ref.p, vel - ref.v, ref.a, 0.02, 0.8, bias))
    plate.set_gains(PidGains(kp=0.0, ki=0.0, kd=0.0))
    plate.reset()
    assert plate.gains.kp == 0.0 and plate.step(pos, vel, ref, 0.02) == pytest.approx(tuple(-ref.a / K_G))
