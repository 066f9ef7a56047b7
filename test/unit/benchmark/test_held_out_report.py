"""The benchmark's table in two sections, the tuning set's and the held-out set's, each
closed by one summary line per controller; the step columns where a domain has force steps;
the set kept in the CSV."""
import math
from types import SimpleNamespace

from ball_balance.benchmark.episode import EpisodeSpec
from ball_balance.benchmark.report import aggregate, format_table, read_csv, write_csv


def fake(domain, controller="pid", **metrics):
    base = dict(drop=0.0, rmse_m=0.01, rmse_steady_m=0.002, settle_s=2.0, peak_tilt_rad=0.05, smoothness_rad_s=0.1,
                latency_s=0.03, engaged_frac=1.0, rmse_release_m=0.01, tick_p99_us=10.0)
    return SimpleNamespace(spec=EpisodeSpec(controller=controller, domain=domain), metrics={**base, **metrics})


def test_the_table_has_a_section_and_a_summary_per_set(tmp_path):
    results = [fake("standard"), fake("pushes", pushes=3.0, pushes_late=1.0, push_recover_s=0.8,
                                      push_recover_max_s=1.2),
               fake("force_2deg", rmse_steady_m=0.012, steps=3.0, steps_unrecovered=1.0, step_recover_s=math.inf,
                    step_recover_max_s=math.inf, step_steady_m=0.009),
               fake("force_2deg", controller="mpc", steps=3.0, steps_unrecovered=0.0, step_recover_s=0.7,
                    step_recover_max_s=0.9, step_steady_m=0.001)]
    rows = aggregate(results)
    assert {r["domain"]: r["set"] for r in rows} == {"standard": "tuning", "pushes": "tuning",
                                                     "force_2deg": "held_out"}
    lines = format_table(rows).splitlines()
    tuning = next(i for i, line in enumerate(lines) if line.startswith("-- tuning set"))
    held = next(i for i, line in enumerate(lines) if line.startswith("-- held-out set"))
    assert 0 < tuning < held
    summaries = [line.strip() for line in lines if " cells, " in line]
    assert summaries[0].startswith("tuning pid: 2 cells, 2 episodes, drops 0") and "pushes late 1/3" in summaries[0]
    assert any(s.startswith("held_out pid: 1 cells") and "steps not back within 5 mm 1/3, worst inf s" in s
               for s in summaries)
    assert "worst 12.0 mm (stationary/force_2deg)" in "\n".join(summaries)
    pid_row = next(line for line in lines if line.startswith("pid") and "force_2deg" in line)
    assert "inf" in pid_row and "9.0" in pid_row
    # the CSV keeps the set, and a table from it is the same
    write_csv(rows, tmp_path / "cells.csv")
    again = read_csv(tmp_path / "cells.csv")
    assert [r["set"] for r in again] == [r["set"] for r in rows]
    assert format_table(again) == format_table(rows)
    # a table of tuning domains only has no step columns
    assert "ss mm" not in format_table([r for r in rows if r["set"] == "tuning"])
