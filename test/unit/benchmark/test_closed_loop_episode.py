"""The closed-loop benchmark episode: reproducible from its seed, it balances, and its spec
expresses pushes, forces, occlusions, the ball type, knob overrides and the reference protocol."""
import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest

from ball_balance.benchmark.episode import (
    REFERENCES,
    EpisodeSpec,
    Exposure,
    Force,
    Occlusion,
    Push,
    controller_values,
    episode_events,
    episode_knobs,
    reference_protocol,
    run_episode,
)
from ball_balance.benchmark.metrics import episode_metrics, recovery_times
from ball_balance.benchmark.report import aggregate, format_table, late_pushes
from ball_balance.control import config as control_config
from ball_balance.sim.config import SimConfigError


def test_same_seed_same_result_and_the_ball_is_balanced():
    spec = EpisodeSpec(controller="pid", domain="standard", reference="stationary", seed=4, duration_s=4.0)
    first, second = run_episode(spec), run_episode(spec)
    assert first.metrics["rmse_m"] == second.metrics["rmse_m"]
    assert first.metrics["drop"] == 0.0 and first.metrics["settle_s"] < 4.0


def test_mpc_episode_reports_solver_times_and_the_table_prints():
    result = run_episode(EpisodeSpec(controller="mpc", reference="circle", seed=1, duration_s=3.0))
    assert result.metrics["qp_p50_us"] > 0 and result.metrics["qp_fallbacks"] == 0
    assert math.isfinite(result.metrics["peak_tilt_rad"]) and result.metrics["peak_tilt_rad"] <= 0.15 + 1e-9
    table = format_table(aggregate([result]))
    assert "mpc" in table and "circle" in table


def test_pushes_domain_pushes_and_reports_the_recovery_time():
    result = run_episode(EpisodeSpec(controller="pid", domain="pushes", seed=2, duration_s=7.0))
    assert result.metrics["drop"] == 0.0
    # one push at 4 s (0.15 m/s): back within 5 mm in a finite time
    assert 0.0 < result.metrics["push_recover_s"] < 3.0


def test_events_in_the_spec_act_on_the_episode():
    quiet = EpisodeSpec(controller="pid", seed=1, duration_s=4.0, record=True)
    pushed = dataclasses.replace(quiet, events=(Push(2.0, 0.2, 0.0), Force(3.0, 0.05, 0.0, 0.01)))
    a, b = run_episode(quiet), run_episode(pushed)
    assert "push_recover_s" not in a.metrics and "push_recover_max_s" in b.metrics
    late = a.series["t"] > 2.2   # after the push (the series count from the engagement)
    assert b.series["x"][late].max() > a.series["x"][late].max() + 0.01


def test_two_markers_hidden_are_reported_to_the_controller():
    spec = EpisodeSpec(controller="pid", seed=1, duration_s=3.0, events=(Occlusion(1.0, 1.0, (0, 3)),))
    result = run_episode(spec)
    assert result.metrics["drop"] == 0.0 and "engaged_frac" in result.metrics


def test_hand_domains_hide_seeded_markers_at_intervals():
    spec = EpisodeSpec(controller="pid", domain="hand_2", seed=4, duration_s=7.0, record=True)
    events = episode_events(spec, episode_knobs(spec))
    assert [e.t_s for e in events] == [3.0, 6.0] and all(len(e.markers) == 2 for e in events)
    result = run_episode(spec)
    assert np.nanmin(result.series["markers"]) == 2 and np.nanmax(result.series["markers"]) == 4


def test_ball_type_release_speed_and_knobs_come_from_the_spec():
    spec = EpisodeSpec(controller="pid", seed=3, duration_s=3.0, ball="solid", release_speed_m_s=(0.1, 0.1),
                       knobs=(("frame_drop_prob", 0.2), ("stamp_jitter_s", 0.002)))
    knobs = episode_knobs(spec)
    assert knobs.ball_shell is False and knobs.frame_drop_prob == 0.2
    assert run_episode(spec).metrics["drop"] == 0.0
    with pytest.raises(SimConfigError, match="unknown knob"):
        episode_knobs(dataclasses.replace(spec, knobs=(("gravity", 2.0),)))
    with pytest.raises(SimConfigError, match="ball"):
        episode_knobs(dataclasses.replace(spec, ball="glass"))


def test_reference_protocol_releases_near_the_centre_and_reports_its_rmse():
    spec = reference_protocol(EpisodeSpec(controller="pid", seed=5, duration_s=4.0))
    assert spec.release_radius_m == (0.0, 0.02) and spec.duration_s == 20.0
    result = run_episode(dataclasses.replace(spec, duration_s=3.0))
    assert 0.0 < result.metrics["rmse_release_m"] < 0.02
    table = format_table(aggregate([result]))
    assert "reference system's protocol" in table and "34 mm" in table


def test_recovery_time_counts_until_the_error_stays_inside():
    t = np.arange(0.0, 3.0, 0.02)
    err = np.where(t < 1.5, 0.02, 0.001)
    err[(t > 1.6) & (t < 1.7)] = 0.01    # a brief excursion: not yet recovered
    assert recovery_times(t, err, [1.0], dropped=False) == [pytest.approx(0.7, abs=0.03)]
    assert recovery_times(t, np.full_like(t, 0.02), [1.0], dropped=False) == [math.inf]


def test_pushes_that_take_longer_than_the_goal_are_counted_and_summed_over_episodes():
    t = np.arange(0.0, 6.0, 0.01)
    err = np.full_like(t, 0.001)
    err[(t >= 1.0) & (t < 1.8)] = 0.02    # back after 0.8 s
    err[(t >= 3.0) & (t < 4.3)] = 0.02    # back after 1.3 s: late
    zeros = np.zeros_like(t)
    series = {"t": t, "x": err, "y": zeros, "rx": zeros, "ry": zeros, "ux": zeros, "uy": zeros,
              "age": zeros, "mode": np.ones_like(t)}
    m = episode_metrics(series, dropped=False, duration_s=6.0, push_times_s=[1.0, 3.0])
    assert (m["pushes"], m["pushes_late"]) == (2.0, 1.0)
    assert m["push_recover_max_s"] == pytest.approx(1.3, abs=0.02)
    results = [SimpleNamespace(spec=EpisodeSpec(domain="pushes", seed=k), metrics=dict(m, drop=0.0, tick_p99_us=1.0))
               for k in range(3)]
    row = aggregate(results)[0]
    assert (row["pushes"], row["pushes_late"]) == (6.0, 3.0) and late_pushes(row) == "3/6"
    assert late_pushes({"pushes": math.nan}) == "-"   # a CSV written before the count


def test_vision_mode_sees_the_hand_and_the_camera_impairments():
    spec = EpisodeSpec(controller="pid", mode="vision", seed=1, duration_s=2.0, record=True,
                       events=(Occlusion(1.0, 0.6, (2,)), Exposure(0.5, 0.8)),
                       knobs=(("sensor_noise", 3.0), ("blur_exposure_s", 0.004)))
    result = run_episode(spec)
    markers = result.series["markers"]
    assert result.metrics["drop"] == 0.0
    assert markers.max() == 4 and markers.min() == 3


def test_fast_mode_reports_the_pose_uncertainty_of_the_visible_markers():
    from ball_balance.benchmark.episode import fast_position_std_m
    from ball_balance.sim.config import CameraConfig

    stds = [fast_position_std_m(visible, CameraConfig(), 0.3) for visible in ((0, 1, 2, 3), (0, 1, 2), (0, 3), (2,))]
    assert stds == sorted(stds) and 0.0 < stds[0] < 0.001
    assert fast_position_std_m((), CameraConfig(), 0.3) == math.inf


@pytest.mark.parametrize("mode", ["fast", "vision"])
def test_tracker_filter_takes_the_delay_the_plate_shows(mode):
    # 200 ms latency: the tracker's filter ends with the plate's delay (latency + servo lag),
    # measured from the plate's tilt (fast: the truth plus the pose fit's noise; vision: its pose)
    spec = EpisodeSpec(controller="pid", domain="latency_200ms", reference="circle", seed=1, duration_s=4.0,
                       mode=mode)
    assert 0.19 <= run_episode(spec).metrics["tracker_delay_s"] <= 0.24
    fixed = dataclasses.replace(spec, mode="fast", tracker_overrides=(("estimate_plate_cmd_delay", False),
                                                                      ("plate_cmd_delay_s", 0.05)))
    assert run_episode(fixed).metrics["tracker_delay_s"] == 0.05


def test_the_ramped_commands_are_written_at_the_managers_update_rate():
    """EpisodeSpec.command_write_hz models BallBalanceController's writes: one per manager cycle."""
    import yaml

    from harness import ROOT

    manager = yaml.safe_load((ROOT / "config" / "ur_controllers.yaml").read_text())["controller_manager"]
    assert EpisodeSpec().command_write_hz == manager["ros__parameters"]["update_rate"]


def test_the_square_and_the_spiral_csv_build_from_any_working_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)   # the spiral's CSV is found from the repository, not the cwd
    for name, period in (("square", 8.0), ("spiral", 16.0)):
        assert name in REFERENCES
        reference = control_config.reference(controller_values("pid", name))
        assert reference.period_s == pytest.approx(period)
        assert np.all(np.abs(reference.path_points(50)) <= 0.1 + 1e-9)
