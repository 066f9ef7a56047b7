"""The closed-loop benchmark episode: reproducible from its seed, and it balances."""
import math

from ball_balance.benchmark.episode import EpisodeSpec, run_episode
from ball_balance.benchmark.report import aggregate, format_table


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
