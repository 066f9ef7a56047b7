"""Disturbances a user can put into the simulated world: a ball released rolling keeps its
speed, pushes and timed forces change its motion as physics says, the harsher domains exist
and are reproducible."""
import dataclasses

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
