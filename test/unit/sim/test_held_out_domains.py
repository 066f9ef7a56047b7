"""The tuning and held-out domain sets: every domain in exactly one, the tuning set the 19
domains the defaults were chosen on; each held-out domain's knobs are what its description
says, and the plate mounted off level is a real mounting tilt in the model."""
import dataclasses
import math

import numpy as np
import pytest

from ball_balance.sim.config import (
    DOMAIN_DESCRIPTIONS,
    DOMAIN_SETS,
    DOMAINS,
    HELD_OUT_DOMAINS,
    TUNING_DOMAINS,
    DomainKnobs,
    SimConfigError,
    domain_set,
)
from ball_balance.sim.world import SimWorld

TUNING = ("standard", "slippery", "sticky", "heavy_ball", "low_gravity", "high_gravity", "noisy_vision",
          "high_latency", "full_dr", "noise_5mm", "latency_200ms", "extreme_dr", "solid_ball", "pushes",
          "hand_1", "hand_2", "hand_3", "force_3deg_noise", "off_level_pushes_noise")


def test_every_domain_is_in_exactly_one_set():
    members = [name for names in DOMAIN_SETS.values() for name in names]
    assert sorted(members) == sorted(DOMAINS) and len(members) == len(set(members))
    assert set(TUNING_DOMAINS) == set(TUNING) and not set(TUNING_DOMAINS) & set(HELD_OUT_DOMAINS)
    assert all(domain_set(d) == "tuning" for d in TUNING) and domain_set("gravity_1.5g") == "tuning"
    assert all(domain_set(d) == "held_out" for d in HELD_OUT_DOMAINS) and domain_set("moon") == ""
    assert all(DOMAIN_DESCRIPTIONS[d].startswith("held out") for d in HELD_OUT_DOMAINS)


@pytest.mark.parametrize("angle", [1, 2, 3])
def test_force_step_domains_have_their_angle_and_a_seeded_direction(angle):
    name = f"force_{angle}deg"
    knobs = [DomainKnobs.sample(name, seed) for seed in range(6)]
    assert all(k.force_step_deg == angle for k in knobs)
    directions = {k.force_step_dir_deg for k in knobs}
    assert len(directions) == 6 and all(0.0 <= d <= 360.0 for d in directions)
    assert DomainKnobs.sample(name, 4) == knobs[4]
    assert dataclasses.replace(knobs[0], force_step_deg=0.0, force_step_dir_deg=0.0) == DomainKnobs()
    assert f"{angle} deg" in DOMAIN_DESCRIPTIONS[name]


def test_stronger_pushes_are_twice_the_pushes_at_the_same_interval():
    strong, pushes = DomainKnobs.sample("pushes_0.3", 0), DomainKnobs.sample("pushes", 0)
    assert strong.push_speed_m_s == 0.3 == 2 * pushes.push_speed_m_s
    assert strong.push_interval_s == pushes.push_interval_s == 4.0


def test_off_level_pushes_under_noise_and_latency_are_milder_and_stronger_than_the_tuning_ones():
    knobs = DomainKnobs.sample("off_level_pushes_noise_latency", 2)
    tuning = DomainKnobs.sample("off_level_pushes_noise", 2)
    assert knobs.plate_mount_tilt_deg == 1.0 < tuning.plate_mount_tilt_deg
    assert knobs.push_speed_m_s == 0.2 > tuning.push_speed_m_s and knobs.push_interval_s == 4.0
    assert knobs.detection_noise_m == 0.003 and 0.03 <= knobs.latency_s <= 0.15


@pytest.mark.parametrize("combo,parts", [
    ("off_level_pushes_noise", ("off_level_2deg", "pushes", "noisy_vision")),
    ("force_2deg_hand_2", ("force_2deg", "hand_2")),
    ("latency_off_level_heavy", ("high_latency", "off_level_2deg", "heavy_ball")),
    ("force_2deg_noise_latency", ("force_2deg", "noisy_vision", "high_latency")),
    ("force_3deg_noise", ("force_3deg", "noisy_vision")),
])
def test_combinations_have_each_fault_of_their_parts(combo, parts):
    expected = {knob: spec for part in parts for knob, spec in DOMAINS[part].items()}
    assert DOMAINS[combo] == expected
    knobs = DomainKnobs.sample(combo, 3)
    for knob, spec in expected.items():
        value = getattr(knobs, knob)
        assert spec[0] <= value <= spec[1] if isinstance(spec, tuple) else value == spec, knob


@pytest.mark.parametrize("change", [dict(force_step_deg=11.0), dict(force_step_dir_deg=-1.0),
                                    dict(plate_mount_tilt_deg=math.nan), dict(plate_mount_axis_deg=400.0)])
def test_bad_held_out_knobs_are_refused_naming_the_knob(change):
    with pytest.raises(SimConfigError, match=next(iter(change))):
        dataclasses.replace(DomainKnobs(), **change)


def test_the_off_level_plate_is_tilted_on_its_mount_and_rolls_the_ball_as_the_equivalent_force():
    knobs = DomainKnobs.sample("off_level_2deg", 1)
    assert knobs.plate_mount_tilt_deg == 2.0
    level, tilted = SimWorld(), SimWorld(knobs=knobs)
    normal = tilted.plate_pose()[1][:, 2]
    assert math.degrees(math.acos(normal[2])) == pytest.approx(2.0, abs=1e-6)
    axis = math.radians(knobs.plate_mount_axis_deg)
    axis_W = level.plate_pose()[1] @ [math.cos(axis), math.sin(axis), 0.0]   # a plate axis, horizontal
    assert np.dot(normal, axis_W) == pytest.approx(0.0, abs=1e-9) and abs(axis_W[2]) < 1e-9
    # the same arm pose: only the plate's mounting differs
    np.testing.assert_allclose(level.joint_positions(), tilted.joint_positions())
    # downhill = the axis turned by -90 degrees; F = m g sin(2 deg) there on the level plate
    f = knobs.ball_mass_kg * 9.81 * math.sin(math.radians(2.0))
    level.apply_force(f * math.cos(axis - math.pi / 2), f * math.sin(axis - math.pi / 2), 0.4)
    level.advance(0.4)
    tilted.advance(0.4)
    a, b = level.ball_truth(), tilted.ball_truth()
    assert math.hypot(b.x, b.y) > 0.01
    assert (b.x, b.y) == (pytest.approx(a.x, abs=3e-4), pytest.approx(a.y, abs=3e-4))
    level.close()
    tilted.close()
