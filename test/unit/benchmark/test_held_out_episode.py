"""The held-out domains in benchmark episodes: force steps of m g sin(angle) on at 5 s,
turned by 90 degrees at 9 s, off at 13 s, from the domain's mass and gravity; stronger
pushes; the step figures (recovery per step, error left under a step)."""
import dataclasses
import math

import numpy as np
import pytest

from ball_balance.benchmark.episode import (
    EpisodeSpec,
    Force,
    Occlusion,
    Push,
    episode_events,
    episode_knobs,
    run_episode,
    step_times,
)
from ball_balance.benchmark.metrics import episode_metrics
from ball_balance.plate_geometry import GRAVITY_M_S2
from ball_balance.sim.config import FORCE_STEP_OFF_S, FORCE_STEP_ON_S, FORCE_STEP_TURN_S


def forces(spec):
    return [e for e in episode_events(spec, episode_knobs(spec)) if isinstance(e, Force)]


@pytest.mark.parametrize("angle", [1, 2, 3])
def test_force_steps_are_m_g_sin_angle_on_turned_and_off(angle):
    spec = EpisodeSpec(domain=f"force_{angle}deg", seed=5, duration_s=20.0)
    knobs = episode_knobs(spec)
    first, second = forces(spec)
    f = knobs.ball_mass_kg * GRAVITY_M_S2 * knobs.gravity_scale * math.sin(math.radians(angle))
    assert (FORCE_STEP_ON_S, FORCE_STEP_TURN_S, FORCE_STEP_OFF_S) == (5.0, 9.0, 13.0)
    assert (first.t_s, first.t_s + first.duration_s) == (5.0, 9.0)
    assert (second.t_s, second.t_s + second.duration_s) == (9.0, 13.0)
    assert first.step and second.step
    assert math.hypot(first.fx_n, first.fy_n) == pytest.approx(f, rel=1e-12)
    assert math.hypot(second.fx_n, second.fy_n) == pytest.approx(f, rel=1e-12)
    # the seeded direction, then turned by +90 degrees
    phi = math.radians(knobs.force_step_dir_deg)
    assert (first.fx_n, first.fy_n) == (pytest.approx(f * math.cos(phi)), pytest.approx(f * math.sin(phi)))
    assert (second.fx_n, second.fy_n) == (pytest.approx(-first.fy_n), pytest.approx(first.fx_n))
    assert forces(dataclasses.replace(spec, seed=6))[0] != first


def test_the_force_comes_from_the_domains_mass_and_gravity():
    spec = EpisodeSpec(domain="force_2deg", seed=1, knobs=(("ball_mass_kg", 0.005), ("gravity_scale", 1.5)))
    first = forces(spec)[0]
    assert math.hypot(first.fx_n, first.fy_n) == pytest.approx(0.005 * 9.81 * 1.5 * math.sin(math.radians(2.0)))
    assert math.hypot(first.fx_n, first.fy_n) == pytest.approx(0.924e-3 * 1.5 * 5.0 / 2.7, rel=1e-3)


def test_force_steps_after_the_end_are_left_out_and_combinations_keep_every_fault():
    assert [e.t_s for e in forces(EpisodeSpec(domain="force_1deg", duration_s=8.0))] == [5.0]
    assert forces(EpisodeSpec(domain="standard")) == []
    spec = EpisodeSpec(domain="force_2deg_hand_2", seed=2, duration_s=20.0)
    events = episode_events(spec, episode_knobs(spec))
    assert [e.t_s for e in events if isinstance(e, Force)] == [5.0, 9.0]
    assert [e.t_s for e in events if isinstance(e, Occlusion)] == [3.0 * k for k in range(1, 7)]


def test_stronger_pushes_push_at_0_3_m_s_every_4_s():
    spec = EpisodeSpec(domain="pushes_0.3", seed=3, duration_s=20.0)
    pushes = episode_events(spec, episode_knobs(spec))
    assert [p.t_s for p in pushes] == [4.0, 8.0, 12.0, 16.0] and all(isinstance(p, Push) for p in pushes)
    assert all(math.hypot(p.dvx, p.dvy) == pytest.approx(0.3) for p in pushes)


def test_a_force_ending_as_the_next_starts_is_one_step():
    assert step_times([5.0, 9.0 + 1e-9, 9.0, 13.0], 0.005) == [5.0, 9.0, 13.0]


def synthetic(t, err):
    zeros = np.zeros_like(t)
    return {"t": t, "x": err, "y": zeros, "rx": zeros, "ry": zeros, "ux": zeros, "uy": zeros,
            "age": zeros, "mode": np.ones_like(t)}


def test_step_figures_recovery_per_step_and_the_error_left_under_it():
    t = np.arange(0.0, 17.0, 0.01)
    err = np.full_like(t, 0.001)
    err[(t >= 5.0) & (t < 5.6)] = 0.02     # on: back after 0.6 s
    err[(t >= 9.0)] = 0.008                # turned: never back within 5 mm, 8 mm left
    err[(t >= 13.0) & (t < 14.5)] = 0.02   # off: back after 1.5 s
    err[t >= 14.5] = 0.002
    m = episode_metrics(synthetic(t, err), dropped=False, duration_s=17.0, step_times_s=[5.0, 9.0, 13.0])
    assert (m["steps"], m["steps_unrecovered"]) == (3.0, 1.0) and "pushes" not in m
    assert m["step_recover_max_s"] == math.inf and m["step_recover_s"] == math.inf
    assert m["step_steady_m"] == pytest.approx(0.008)   # the worst step's last second
    quiet = episode_metrics(synthetic(t, np.full_like(t, 0.001)), dropped=False, duration_s=17.0)
    assert "steps" not in quiet and "step_steady_m" not in quiet


def test_an_episode_reports_its_held_forces_as_steps_not_pushes():
    held = (Force(1.0, 1.0, 0.0005, 0.0, step=True), Force(2.0, 1.0, 0.0, 0.0005, step=True))
    result = run_episode(EpisodeSpec(controller="pid", seed=1, duration_s=4.0, events=held))
    m = result.metrics
    assert m["drop"] == 0.0 and m["steps"] == 3.0 and "pushes" not in m
    assert m["step_steady_m"] > 0.0 and m["step_recover_max_s"] > 0.0
