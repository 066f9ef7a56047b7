"""offset_free_bench's goal lines: per controller and tracker setting, the episodes whose
every force step and every push meets its goal, with the worst figures, and the drops."""
import importlib.util
import math
from pathlib import Path

PATH = Path(__file__).resolve().parents[3] / "benchmarks" / "offset_free_bench.py"
spec = importlib.util.spec_from_file_location("offset_free_bench", PATH)
bench = importlib.util.module_from_spec(spec)
spec.loader.exec_module(bench)


def row(setting, step=math.nan, steady=math.nan, push=math.nan, drop=0.0, controller="pid"):
    return {"controller": controller, "tracker_disturbance": setting, "rmse_steady_m": 0.001,
            "step_recover_max_s": step, "step_steady_m": steady, "push_recover_max_s": push, "drop": drop}


def test_goal_lines_count_the_episodes_that_meet_each_goal():
    rows = [row("off", step=math.inf, steady=0.02), row("on", step=1.5, steady=0.0005),
            row("on", step=2.6, steady=0.0004), row("on", step=2.0, steady=0.0012),
            row("on", push=1.1), row("on", push=1.3, drop=1.0), row("on", controller="mpc", push=0.9)]
    lines = bench.goal_lines(rows)
    assert lines[0] == "pid (off): force steps within 2.5 s and 1 mm in 0/1 episodes (worst inf s, 20.00 mm); drops 0/1"
    assert lines[1] == ("pid (on): force steps within 2.5 s and 1 mm in 1/3 episodes (worst 2.60 s, 1.20 mm); "
                        "every push within 1.2 s in 1/2 episodes (worst 1.30 s); drops 1/5")
    assert lines[2:] == ["mpc (on): every push within 1.2 s in 1/1 episodes (worst 0.90 s); drops 0/1"]
