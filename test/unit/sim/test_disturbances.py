"""Disturbances a user can put into the simulated world: a ball released rolling keeps its
speed, pushes and timed forces change its motion as physics says, the harsher domains exist
and are reproducible."""
import dataclasses
import math

import pytest

from ball_balance.plate_geometry import ROLLING_FACTOR_SHELL, ROLLING_FACTOR_SOLID
from ball_balance.sim.config import (
    DOMAIN_ALIASES,
    DOMAIN_DESCRIPTIONS,
    DOMAINS,
    DomainKnobs,
    SimConfig,
    SimConfigError,
)
from ball_balance.sim.world import CommandError, SimWorld


@pytest.fixture(scope="module", params=[True, False], ids=["shell", "solid"])
def world(request):
    world = SimWorld(SimConfig(ball_shell=request.param))
    yield world
    world.close()


def test_ball_released_rolling_keeps_its_speed(world):
    world.reset()
    world.place_ball(-0.05, 0.02, vx=0.2, vy=-0.1)
    world.advance(0.3)
    truth = world.ball_truth()
    # without spin the ball lost 2/5 (shell) or 2/7 (solid) of its speed to slip at once
    assert truth.vx == pytest.approx(0.2, rel=0.03) and truth.vy == pytest.approx(-0.1, rel=0.03)
    assert truth.x == pytest.approx(-0.05 + 0.3 * 0.2, abs=0.002)


def test_push_changes_the_velocity_and_the_ball_keeps_rolling(world):
    world.reset()
    world.advance(0.05)
    world.push_ball(0.0, 0.15)
    world.advance(0.3)
    truth = world.ball_truth()
    assert truth.vy == pytest.approx(0.15, rel=0.03) and abs(truth.vx) < 1e-3


def test_timed_force_gives_the_rolling_ball_k_f_t_over_m(world):
    world.reset()
    world.advance(0.05)
    world.apply_force(0.01, 0.0, 0.05)
    world.advance(0.3)   # force over after 0.05 s, then the ball rolls on
    k = ROLLING_FACTOR_SHELL if world.config.ball_shell else ROLLING_FACTOR_SOLID
    expected = k * 0.01 * 0.05 / world.knobs.ball_mass_kg
    assert world.ball_truth().vx == pytest.approx(expected, rel=0.05)
    assert not world.data.xfrc_applied[world.ids.ball_body].any()


def test_bad_disturbances_are_refused(world):
    with pytest.raises(CommandError, match="finite"):
        world.push_ball(float("nan"), 0.0)
    with pytest.raises(CommandError, match="duration"):
        world.apply_force(0.01, 0.0, -1.0)
    with pytest.raises(CommandError, match="duration"):
        world.apply_force(0.01, 0.0, float("nan"))


def _rolling_gain(world):
    """k / m: the rolling ball's acceleration per newton on its centre."""
    k = ROLLING_FACTOR_SHELL if world.config.ball_shell else ROLLING_FACTOR_SOLID
    return k / world.knobs.ball_mass_kg


def test_held_force_acts_until_replaced_and_zero_ends_it(world):
    world.reset()
    world.advance(0.05)
    world.hold_force(0.002, 0.0)
    world.advance(0.2)
    a = _rolling_gain(world) * 0.002
    assert world.ball_truth().vx == pytest.approx(a * 0.2, rel=0.05)
    world.hold_force(0.0, 0.002)            # replaces the first: x keeps its speed, y gains
    world.advance(0.2)
    truth = world.ball_truth()
    assert truth.vx == pytest.approx(a * 0.2, rel=0.05) and truth.vy == pytest.approx(a * 0.2, rel=0.05)
    world.hold_force(0.0, 0.0)
    world.advance(0.1)
    assert world.ball_truth().vy == pytest.approx(truth.vy, rel=0.03)
    assert not world.data.xfrc_applied[world.ids.ball_body].any()


def test_timed_forces_add_to_the_held_force_and_clear_forces_ends_both(world):
    world.reset()
    world.advance(0.05)
    world.hold_force(0.002, 0.0)
    world.apply_force(0.002, 0.0, 0.1)
    world.advance(0.2)   # 0.004 N for 0.1 s, then 0.002 N for 0.1 s
    assert world.ball_truth().vx == pytest.approx(_rolling_gain(world) * 0.006 * 0.1, rel=0.05)
    world.clear_forces()
    world.advance(0.01)
    assert not world.data.xfrc_applied[world.ids.ball_body].any()


def test_a_bad_held_force_is_refused_and_the_one_in_effect_stays(world):
    world.reset()
    world.hold_force(0.002, 0.0)
    with pytest.raises(CommandError, match="finite"):
        world.hold_force(float("inf"), 0.0)
    world.advance(0.01)
    assert math.hypot(*world.data.xfrc_applied[world.ids.ball_body][:3]) == pytest.approx(0.002)
    world.clear_forces()


def test_a_tilt_force_rolls_the_ball_as_the_tilted_plate_would(world):
    world.reset()
    world.advance(0.05)
    knobs = world.knobs
    fx, fy = knobs.tilt_force_n(2.0, 120.0)
    assert math.hypot(fx, fy) == pytest.approx(knobs.ball_mass_kg * 9.81 * math.sin(math.radians(2.0)))
    world.hold_force(fx, fy)
    world.advance(0.3)
    k = ROLLING_FACTOR_SHELL if world.config.ball_shell else ROLLING_FACTOR_SOLID
    speed = k * 9.81 * math.sin(math.radians(2.0)) * 0.3   # x'' = k g sin(tilt)
    truth = world.ball_truth()
    assert (truth.vx, truth.vy) == (pytest.approx(speed * math.cos(math.radians(120.0)), rel=0.05),
                                    pytest.approx(speed * math.sin(math.radians(120.0)), rel=0.05))
    world.clear_forces()


def test_force_steps_of_a_domain_are_on_turned_and_off():
    knobs = DomainKnobs.sample("force_3deg", 4)
    (on, duration1, fx1, fy1), (turn, duration2, fx2, fy2) = knobs.force_steps()
    assert (on, on + duration1, turn, turn + duration2) == (5.0, 9.0, 9.0, 13.0)
    assert (fx1, fy1) == pytest.approx(knobs.tilt_force_n(3.0, knobs.force_step_dir_deg))
    assert (fx2, fy2) == pytest.approx((-fy1, fx1))
    assert DomainKnobs().force_steps() == ()


def test_the_domain_chooses_the_ball():
    knobs = DomainKnobs.sample("solid_ball", 0)
    world = SimWorld(knobs=knobs)
    assert not world.config.ball_shell and world.config.rolling_factor == ROLLING_FACTOR_SOLID
    world.close()


def test_harsher_domains_of_the_reference_system_are_there():
    assert DomainKnobs.sample("noise_5mm", 0).detection_noise_m == 0.005
    assert DomainKnobs.sample("latency_200ms", 0).latency_s == 0.2
    assert DomainKnobs.sample("gravity_0.5g", 0).gravity_scale == 0.5
    assert DomainKnobs.sample("gravity_1.5g", 0) == DomainKnobs.sample("high_gravity", 0)
    assert set(DOMAIN_ALIASES.values()) <= set(DOMAINS)
    assert set(DOMAIN_DESCRIPTIONS) == set(DOMAINS)
    pushes = DomainKnobs.sample("pushes", 0)
    assert pushes.push_speed_m_s == 0.15 and pushes.push_interval_s > 0


def test_extreme_dr_is_wider_than_full_dr_in_every_range():
    full, extreme = DOMAINS["full_dr"], DOMAINS["extreme_dr"]
    for knob, (low, high) in full.items():
        assert extreme[knob][0] <= low and extreme[knob][1] >= high, knob
        assert extreme[knob] != (low, high), knob
    balls = {DomainKnobs.sample("extreme_dr", seed).ball_shell for seed in range(20)}
    assert balls == {True, False}
    assert DomainKnobs.sample("extreme_dr", 3) == DomainKnobs.sample("extreme_dr", 3)


@pytest.mark.parametrize("change,message", [
    (dict(frame_drop_prob=1.0), "frame_drop_prob"),
    (dict(ball_shell="yes"), "ball_shell"),
    (dict(push_speed_m_s=0.1), "push_interval_s"),
    (dict(occlusion_markers=5), "occlusion_markers"),
    (dict(occlusion_markers=2, occlusion_interval_s=1.0, occlusion_duration_s=2.0), "occlusion"),
])
def test_bad_knobs_are_refused_naming_the_knob(change, message):
    with pytest.raises(SimConfigError, match=message):
        dataclasses.replace(DomainKnobs(), **change)
