import numpy as np
from control_plant import K_G, DelayedPlant

from ball_balance.control.pid import AxisPid, PidGains, PlatePid
from ball_balance.control.references import Stationary


def test_ball_right_of_reference_gets_positive_tilt_that_drives_it_toward_minus_x():
    pid = PlatePid(PidGains(), K_G)
    u = pid.step(np.array([0.05, -0.05]), np.zeros(2), Stationary().sample(0.0), 0.02)
    assert u[0] > 0 and u[1] < 0
    plant = DelayedPlant(x0=(0.05, -0.05))
    plant.advance(u, 0.1)
    assert plant.v[0] < 0 and plant.v[1] > 0


def test_output_is_clipped():
    pid = AxisPid(PidGains(u_max_rad=0.1), K_G)
    assert pid.step(10.0, 10.0, 0.0, 0.02) == 0.1
    assert pid.step(-10.0, -10.0, 0.0, 0.02) == -0.1


def test_integral_does_not_wind_up_while_saturated():
    gains = PidGains(ki=2.0, u_max_rad=0.1, i_limit_rad=0.05, i_zone_m=1.0)
    pid = AxisPid(gains, K_G)
    for _ in range(500):  # 10 s pinned at saturation
        pid.step(0.2, 0.0, 0.0, 0.02)
    assert abs(gains.ki * pid.integral) <= 0.05 + 1e-12
    # as soon as the error reverses, the output leaves saturation immediately
    assert pid.step(-0.02, 0.0, 0.0, 0.02) < 0.1


def test_deadband_stops_integration_on_tiny_errors():
    pid = AxisPid(PidGains(deadband_m=0.002), K_G)
    for _ in range(100):
        pid.step(0.0015, 0.0, 0.0, 0.02)
    assert pid.integral == 0.0


def test_derivative_uses_measured_velocity():
    g = PidGains(kp=0.0, ki=0.0, kd=1.0)
    assert AxisPid(g, K_G).step(0.0, 0.3, 0.0, 0.02) == 0.15  # clipped at default u_max
    assert AxisPid(g, K_G).step(0.0, 0.1, 0.0, 0.02) == 0.1


def test_closed_loop_settles_from_off_centre_release():
    pid = PlatePid(PidGains(), K_G)
    plant = DelayedPlant(x0=(0.1, -0.08), delay_s=0.04)
    ref = Stationary().sample(0.0)
    for _ in range(400):  # 8 s at 50 Hz
        u = pid.step(plant.p, plant.v, ref, 0.02)
        plant.advance(u, 0.02)
    assert np.linalg.norm(plant.p) < 0.002
