"""The simulated arm keeps to the URDF's position and velocity limits in the physics, commanded
or not: the 50 rad forward command of the fault probe (clamped to the limits by the manager),
the move back home, every joint at once, and random full-range moves."""
import numpy as np
import pytest

from ball_balance import robot
from ball_balance.sim.world import SimWorld

HOME = np.array(robot.HOME_POSITIONS_RAD)


@pytest.fixture(scope="module")
def world():
    world = SimWorld()
    yield world
    world.close()


def follow(world, target, seconds):
    """Command `target` and step; the worst excursion past the position limits (rad) and the
    worst |velocity| / velocity limit over the move."""
    world.set_joint_targets(target)
    beyond, speed = np.zeros(6), np.zeros(6)
    for _ in range(int(round(seconds / world.physics_dt_s))):
        world.step()
        q, v = world.joint_positions(), world.joint_velocities()
        beyond = np.maximum(beyond, np.maximum(q - world.upper_rad, world.lower_rad - q))
        speed = np.maximum(speed, np.abs(v) / world.max_velocity_rad_s)
    return beyond, speed


def clamped(world, q):
    return np.clip(q, world.lower_rad, world.upper_rad)


@pytest.mark.parametrize("commanded,servo_alone", [((0, 2), True), ((0, 1, 2, 3, 4, 5), False)],
                         ids=["pan_and_elbow", "every_joint"])
def test_50_rad_command_and_the_move_home_stay_within_the_limits(world, commanded, servo_alone):
    world.reset()
    target = HOME.copy()
    target[list(commanded)] = 50.0
    guard_before = world.limit_guard_count
    for goal in (clamped(world, target), HOME):
        beyond, speed = follow(world, goal, 6.0)
        assert np.all(beyond <= 0.0), f"past the position limits by {beyond} rad"
        assert np.all(speed <= 1.0), f"velocity / limit {speed}"
    # the fault probe's case: the servo holds the limits by itself (the last-resort guard never
    # acted); every joint at full speed at once: the coupling needs the guard now and then
    if servo_alone:
        assert world.limit_guard_count == guard_before
    assert np.allclose(world.joint_positions(), HOME, atol=1e-3)


def test_a_command_at_the_limit_is_reached_to_within_a_milliradian(world):
    world.reset()
    target = HOME.copy()
    target[0] = world.upper_rad[0]
    follow(world, target, 5.0)
    assert world.upper_rad[0] - 2e-3 < world.joint_positions()[0] <= world.upper_rad[0]


def test_random_full_range_moves_never_exceed_the_limits(world):
    world.reset()
    rng = np.random.default_rng(3)
    for _ in range(12):
        beyond, speed = follow(world, rng.uniform(world.lower_rad, world.upper_rad), 0.25)
        assert np.all(beyond <= 0.0) and np.all(speed <= 1.0)


def test_speed_scaling_scales_the_velocity_the_servo_asks_for(world):
    world.reset()
    world.speed_scaling = 0.5
    try:
        target = HOME.copy()
        target[5] += 1.0
        _, speed = follow(world, target, 1.0)
        assert 0.3 < speed[5] <= 0.5
    finally:
        world.speed_scaling = 1.0
