"""The benchmark's paired comparison: each controller against the baseline over the same seeds,
the mean difference with its 95 % interval, and the per-episode CSV it is read back from."""
import math

import pytest

from ball_balance.benchmark.report import (
    EPISODE_COLUMNS,
    format_paired_table,
    paired_comparison,
    read_csv,
    verdict,
    write_csv,
)


def episode(controller, seed, rmse_mm, domain="standard", drop=0.0):
    row = {key: math.nan for key in EPISODE_COLUMNS}
    row.update(controller=controller, protocol="ours", reference="circle", domain=domain, seed=seed, drop=drop,
               rmse_steady_mm=rmse_mm)
    return row


def test_a_difference_every_seed_shows_is_below_or_above():
    base = [1.0, 1.2, 0.9, 1.1, 1.05]
    episodes = ([episode("pid", s, v) for s, v in enumerate(base)]
                + [episode("policy", s, v - 0.1 - 0.01 * s) for s, v in enumerate(base)]
                + [episode("mpc", s, v + 0.2) for s, v in enumerate(base)])
    rows = {r["controller"]: r for r in paired_comparison(episodes, "pid")}
    assert set(rows) == {"mpc", "policy"}
    assert rows["policy"]["pairs"] == 5 and rows["policy"]["lower"] == 5
    assert rows["policy"]["mean_diff"] == pytest.approx(-0.12)
    # Student's t for 4 degrees of freedom: 2.776 x the standard error of the differences
    assert rows["policy"]["ci_half"] == pytest.approx(2.776 * 0.01 * math.sqrt(2.5) / math.sqrt(5), rel=1e-3)
    assert verdict(rows["policy"]) == "below"
    assert rows["mpc"]["higher"] == 5 and verdict(rows["mpc"]) == "above"


def test_differences_of_either_sign_are_a_tie_and_identical_runs_are_equal():
    episodes = ([episode("pid", s, 1.0) for s in range(4)]
                + [episode("policy", s, 1.0 + d) for s, d in enumerate([0.01, -0.01, 0.02, -0.015])]
                + [episode("same", s, 1.0) for s in range(4)])
    rows = {r["controller"]: r for r in paired_comparison(episodes, "pid")}
    assert verdict(rows["policy"]) == "tie"
    assert verdict(rows["same"]) == "equal"


def test_only_seeds_both_ran_and_both_kept_the_ball_are_paired_and_drops_are_counted():
    episodes = [episode("pid", 0, 1.0), episode("pid", 1, 1.0), episode("pid", 2, 1.0, drop=1.0),
                episode("policy", 0, 0.9), episode("policy", 1, 0.8, drop=1.0), episode("policy", 2, 0.7),
                episode("policy", 3, 0.5)]
    (row,) = paired_comparison(episodes, "pid")
    assert row["pairs"] == 1 and row["drops"] == 1 and row["baseline_drops"] == 1
    assert row["mean_diff"] == pytest.approx(-0.1) and math.isnan(row["ci_half"])
    assert verdict(row) == "-"
    assert "policy" in format_paired_table([row])


def test_cells_are_compared_apart():
    episodes = [episode("pid", 0, 1.0, "a"), episode("policy", 0, 2.0, "a"),
                episode("pid", 0, 1.0, "b"), episode("policy", 0, 0.5, "b")]
    rows = {r["domain"]: r["mean_diff"] for r in paired_comparison(episodes, "pid")}
    assert rows == {"a": pytest.approx(1.0), "b": pytest.approx(-0.5)}


def test_episode_rows_survive_the_csv(tmp_path):
    rows = [episode("pid", 3, 0.123456789), episode("policy", 3, 0.5, drop=1.0)]
    write_csv(rows, tmp_path / "e.csv", EPISODE_COLUMNS)
    back = read_csv(tmp_path / "e.csv")
    assert [r["seed"] for r in back] == [3, 3] and back[1]["drop"] == 1.0
    assert back[0]["rmse_steady_mm"] == pytest.approx(0.123457) and math.isnan(back[0]["settle_s"])
    assert back[0]["controller"] == "pid" and back[0]["domain"] == "standard"


def test_an_episode_result_becomes_one_row_in_millimetres():
    from ball_balance.benchmark.episode import EpisodeResult, EpisodeSpec
    from ball_balance.benchmark.report import episode_rows

    result = EpisodeResult(EpisodeSpec(controller="mpc", domain="pushes", reference="circle", seed=7),
                           {"drop": 0.0, "rmse_steady_m": 0.0021, "pushes": 3.0, "qp_p99_us": 80.0})
    (row,) = episode_rows([result])
    assert row["seed"] == 7 and row["domain"] == "pushes" and row["protocol"] == "ours"
    assert row["rmse_steady_mm"] == pytest.approx(2.1) and row["pushes"] == 3.0 and math.isnan(row["settle_s"])
    assert set(row) == set(EPISODE_COLUMNS)
