"""SimWorld physics: the ball rolls like a thin shell, the arm servos follow with a few ms
lag, bad commands are refused, drops are detected, domain knobs are reproducible."""
import math

import numpy as np
import pytest

from ball_balance import robot
from ball_balance.plate_geometry import BALL_MASS_KG, GRAVITY_M_S2, ROLLING_FACTOR_SHELL, ROLLING_FACTOR_SOLID
from ball_balance.sim.config import DOMAINS, CameraConfig, DomainKnobs, SimConfig, SimConfigError
from ball_balance.sim.world import CommandError, SimWorld


@pytest.fixture(scope="module")
def world():
    world = SimWorld()
    yield world
    world.close()


def tilted_home(joint_index: int, delta_rad: float) -> np.ndarray:
    q = np.array(robot.HOME_POSITIONS_RAD)
    q[joint_index] += delta_rad
    return q


@pytest.fixture(scope="module")
def solid_world():
    world = SimWorld(SimConfig(ball_shell=False))
    yield world
    world.close()


@pytest.mark.parametrize("joint_index,delta_rad,shell", [(3, 0.1, True), (4, -0.06, True), (3, 0.08, False)])
def test_ball_released_on_tilted_plate_accelerates_as_its_rolling_model_predicts(
        world, solid_world, joint_index, delta_rad, shell):
    world = world if shell else solid_world
    world.reset(tilted_home(joint_index, delta_rad))
    world.advance(0.02)  # settle into contact
    _, R_WP = world.plate_pose()
    tilt_rad = math.acos(R_WP[2, 2])
    t, s = [], []
    start = world.ball_truth()
    for _ in range(300):
        world.step()
        truth = world.ball_truth()
        t.append(truth.time_s - start.time_s)
        s.append(math.hypot(truth.x - start.x, truth.y - start.y))
    t = np.array(t)
    # s(t) = s0 + v0 t + a t^2 / 2, least squares
    _, _, a = np.linalg.lstsq(np.stack([np.ones_like(t), t, 0.5 * t * t], 1), np.array(s), rcond=None)[0]
    factor = ROLLING_FACTOR_SHELL if shell else ROLLING_FACTOR_SOLID
    expected = factor * GRAVITY_M_S2 * math.sin(tilt_rad)
    assert world.config.rolling_factor == factor
    assert a == pytest.approx(expected, rel=0.05)


def test_ball_rests_on_level_plate(world):
    world.reset()
    world.advance(1.0)
    truth = world.ball_truth()
    assert math.hypot(truth.x, truth.y) < 1e-3 and not world.ball_dropped


def test_arm_follows_a_joint_target_with_a_few_milliseconds_lag(world):
    world.reset()
    target = tilted_home(4, 0.01)
    world.set_joint_targets(target)
    crossed = None
    for _ in range(200):
        world.step()
        progress = (world.joint_positions()[4] - robot.HOME_POSITIONS_RAD[4]) / 0.01
        if crossed is None and progress >= 0.63:
            crossed = world.time_s
    assert crossed is not None and 0.002 <= crossed <= 0.03
    assert np.allclose(world.joint_positions(), target, atol=1e-4)


def test_joint_velocity_is_limited_by_the_urdf(world):
    world.reset()
    world.set_joint_targets(tilted_home(5, 1.0))
    peak = 0.0
    for _ in range(200):
        world.step()
        peak = max(peak, abs(world.joint_velocities()[5]))
    assert peak <= 3.14 * 1.05


@pytest.mark.parametrize("command,message", [
    ([0.0, -1.5, 1.5, -1.5, math.nan, 0.0], "non-finite"),
    ([0.0, -1.5, 1.5, -1.5, math.inf, 0.0], "non-finite"),
    ([0.0, -1.5, 4.0, -1.5, 1.5, 0.0], "elbow_joint"),
    ([0.0, 1.0], "6 numbers"),
])
def test_bad_joint_command_is_refused_and_the_last_target_kept(world, command, message):
    world.reset()
    with pytest.raises(CommandError, match=message):
        world.set_joint_targets(command)
    world.advance(0.05)
    assert np.allclose(world.joint_positions(), robot.HOME_POSITIONS_RAD, atol=1e-6)


def test_ball_off_the_plate_is_reported_dropped(world):
    world.reset(ball_xy=(0.2, 0.0))
    world.place_ball(0.2, 0.0, vx=0.5)
    world.advance(0.3)
    assert world.ball_dropped and world.ball_truth().dropped
    world.reset()
    assert not world.ball_dropped


def test_latency_knob_delays_joint_commands():
    world = SimWorld(knobs=DomainKnobs(latency_s=0.05))
    world.set_joint_targets(tilted_home(4, 0.01))
    world.advance(0.04)
    assert world.joint_positions()[4] == pytest.approx(robot.HOME_POSITIONS_RAD[4], abs=1e-6)
    world.advance(0.06)
    assert world.joint_positions()[4] == pytest.approx(robot.HOME_POSITIONS_RAD[4] + 0.01, abs=1e-3)


def test_domain_knobs_reach_the_model():
    world = SimWorld(knobs=DomainKnobs(ball_mass_kg=0.005, ball_friction=0.9, gravity_scale=1.5))
    model = world.model
    assert model.body_mass[world.ids.ball_body] == pytest.approx(0.005)
    assert model.geom_friction[model.geom("ball").id][0] == pytest.approx(0.9)
    assert model.opt.gravity[2] == pytest.approx(-9.81 * 1.5)


def test_domains_are_reproducible_from_the_seed():
    assert DomainKnobs.sample("full_dr", 7) == DomainKnobs.sample("full_dr", 7)
    assert DomainKnobs.sample("full_dr", 7) != DomainKnobs.sample("full_dr", 8)
    assert DomainKnobs.sample("standard", 3) == DomainKnobs()
    assert DomainKnobs.sample("heavy_ball", 0).ball_mass_kg > BALL_MASS_KG
    latency = DomainKnobs.sample("high_latency", 1).latency_s
    assert 0.03 <= latency <= 0.15
    assert set(DOMAINS) >= {"standard", "slippery", "sticky", "heavy_ball", "low_gravity",
                            "high_gravity", "noisy_vision", "high_latency", "full_dr"}


def test_detection_noise_is_seeded():
    knobs = DomainKnobs(detection_noise_m=0.003)
    a, b = SimWorld(knobs=knobs, seed=5), SimWorld(knobs=knobs, seed=5)
    samples = [a.detected_ball() for _ in range(200)]
    assert samples[:3] == [b.detected_ball() for _ in range(3)]
    assert 0.002 < np.std(np.array(samples)[:, 0]) < 0.004


@pytest.mark.parametrize("make,message", [
    (lambda: CameraConfig(width_px=0), "width_px"),
    (lambda: CameraConfig(height_px=0), "height_px"),
    (lambda: SimConfig(physics_dt_s=0.0), "physics_dt_s"),
    (lambda: SimConfig(physics_dt_s=0.002, servo_lag_s=0.002), "servo_lag_s"),
    (lambda: DomainKnobs(ball_mass_kg=math.nan), "ball_mass_kg"),
    (lambda: DomainKnobs.sample("underwater", 0), "unknown domain"),
])
def test_bad_settings_are_refused_naming_the_setting(make, message):
    with pytest.raises(SimConfigError, match=message):
        make()


def test_diverged_physics_is_reported_and_the_world_reset(world):
    from ball_balance.sim.world import SimulationError

    world.reset()
    world.set_joint_targets(tilted_home(4, 0.02))
    world.advance(0.1)
    world.data.qvel[world.ids.ball_dof] = 1e20
    with pytest.raises(SimulationError, match="diverged"):
        world.step()
    assert np.allclose(world.joint_positions(), tilted_home(4, 0.02))
    assert world.time_s == pytest.approx(0.101) and world.ball_truth().on_plate
