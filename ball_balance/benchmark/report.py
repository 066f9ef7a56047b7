"""Aggregate episodes into a table (stdout), a CSV and a bar plot; one CSV row per episode, and
each controller against a baseline over the same seeds (paired differences)."""
from __future__ import annotations

import csv
import math
from collections import defaultdict
from pathlib import Path
from typing import Dict, List

import numpy as np

from ball_balance.sim.config import domain_set

# docs/design.md section 7: the reference system's PID (RMSE mm over the steps before a drop, its
# protocol: released 0-2 cm off centre, 600 steps at 30 Hz), where stated
REFERENCE_FIGURES = {"standard": "34 mm", "high_gravity": "117 mm, 70 % drops", "gravity_1.5g": "117 mm, 70 % drops",
                     "sticky": "33 % drops"}

COLUMNS = ("controller", "protocol", "reference", "domain", "set", "episodes", "drop_rate", "rmse_steady_mm",
           "settle_s", "push_recover_s", "push_recover_max_s", "pushes", "pushes_late", "step_recover_s",
           "step_recover_max_s", "steps", "steps_unrecovered", "step_steady_mm", "engaged_pct", "rmse_mm",
           "rmse_release_mm", "peak_tilt_deg", "smoothness_rad_s", "latency_ms", "tick_p99_us", "qp_p50_us",
           "qp_p99_us", "qp_p99_worst_us", "qp_fallbacks")

# one row per episode (closed_loop_episodes.csv): what the paired comparison needs, and the
# figures the cell rows summarise (their worst case)
EPISODE_FIGURES = ("settle_s", "push_recover_max_s", "pushes", "pushes_late", "step_recover_max_s", "steps",
                   "steps_unrecovered", "tick_p99_us", "qp_p99_us")
EPISODE_COLUMNS = ("controller", "protocol", "reference", "domain", "set", "seed", "drop", "rmse_steady_mm",
                   "step_steady_mm", *EPISODE_FIGURES)
CELL = ("protocol", "reference", "domain")
TEXT_COLUMNS = ("controller", "set") + CELL


def episode_rows(results) -> List[Dict[str, float]]:
    """One row per episode (EPISODE_COLUMNS; a figure the episode does not have is nan)."""
    rows = []
    for r in results:
        m = r.metrics
        rows.append({
            "controller": r.spec.controller, "protocol": getattr(r.spec, "protocol", "ours"),
            "reference": r.spec.reference, "domain": r.spec.domain, "set": domain_set(r.spec.domain),
            "seed": int(r.spec.seed), "drop": float(m["drop"]),
            "rmse_steady_mm": 1e3 * m.get("rmse_steady_m", math.nan),
            "step_steady_mm": 1e3 * m.get("step_steady_m", math.nan),
            **{key: float(m.get(key, math.nan)) for key in EPISODE_FIGURES}})
    return rows


def paired_comparison(episodes, baseline: str = "pid", metric: str = "rmse_steady_mm",
                      confidence: float = 0.95) -> List[Dict[str, float]]:
    """Each controller against `baseline` in each cell, over the seeds both ran and both kept
    the ball: the mean of the per-seed differences (controller - baseline) of `metric`, its
    two-sided `confidence` interval (Student's t over the pairs), and how many seeds went
    each way. A seed is the same episode for both controllers (domain draws, pushes, noise),
    so the pairs cancel what the seed decides and a difference within the interval's reach of
    zero is a tie, whatever its sign."""
    from scipy import stats

    by_cell = defaultdict(dict)
    for e in episodes:
        by_cell[tuple(e[k] for k in CELL)][(e["controller"], int(e["seed"]))] = e
    rows = []
    for cell, runs in by_cell.items():
        for controller in sorted({c for c, _ in runs} - {baseline}):
            pairs = [(runs[(controller, seed)], base) for (c, seed), base in runs.items()
                     if c == baseline and (controller, seed) in runs]
            kept = [(a[metric], b[metric]) for a, b in pairs if not (a["drop"] or b["drop"])]
            diffs = np.array([a - b for a, b in kept], dtype=float)
            n = len(diffs)
            mean = float(np.mean(diffs)) if n else math.nan
            half = (float(stats.t.ppf(0.5 + confidence / 2, n - 1) * np.std(diffs, ddof=1) / math.sqrt(n))
                    if n > 1 else math.nan)
            rows.append({**dict(zip(CELL, cell, strict=True)), "controller": controller, "baseline": baseline,
                         "confidence": confidence, "pairs": n, "drops": sum(a["drop"] for a, _ in pairs),
                         "baseline_drops": sum(b["drop"] for _, b in pairs),
                         "mean_diff": mean, "ci_half": half,
                         "lower": int(np.sum(diffs < 0)), "higher": int(np.sum(diffs > 0)),
                         "baseline_mean": float(np.mean([b for _, b in kept])) if n else math.nan})
    return sorted(rows, key=lambda r: (r["protocol"] != "ours", r["reference"], r["domain"], r["controller"]))


def verdict(row) -> str:
    """'below' / 'above' the baseline when the interval excludes zero, 'equal' when every seed
    gave the same figure, else 'tie'."""
    if row["pairs"] and row["lower"] == row["higher"] == 0:
        return "equal"
    if not math.isfinite(row["ci_half"]):
        return "-"
    if row["mean_diff"] + row["ci_half"] < 0:
        return "below"
    return "above" if row["mean_diff"] - row["ci_half"] > 0 else "tie"


def format_paired_table(rows, metric_label: str = "RMSE>5s") -> str:
    """The paired comparison, one line per controller and cell."""
    if not rows:
        return ""
    width = max([13] + [len(r["domain"]) for r in rows])
    lines = [f"against {rows[0]['baseline']} on the same seeds ({metric_label}: controller - "
             f"{rows[0]['baseline']}, mean and {100 * rows[0]['confidence']:g} % interval over the seeds both kept "
             f"the ball)",
             f"{'controller':10} {'reference':12} {'domain':{width}} {'pairs':>5} {'drops':>7} {'base mm':>8} "
             f"{'diff mm':>9} {'+/- mm':>8} {'diff %':>7} {'lower':>5} {'higher':>6}  verdict"]
    for r in rows:
        pct = 100.0 * r["mean_diff"] / r["baseline_mean"] if r["baseline_mean"] else math.nan
        lines.append(f"{r['controller']:10} {r['reference']:12} {r['domain']:{width}} {r['pairs']:>5} "
                     f"{r['drops']:>3.0f}/{r['baseline_drops']:<3.0f} {r['baseline_mean']:>8.4f} "
                     f"{r['mean_diff']:>+9.4f} {r['ci_half']:>8.4f} {pct:>+7.2f} {r['lower']:>5} {r['higher']:>6}  "
                     f"{verdict(r)}")
    return "\n".join(lines)


def aggregate(results) -> List[Dict[str, float]]:
    """One row per (controller, protocol, reference, domain): means over the episodes (the
    steady-state and timing figures over the episodes that kept the ball)."""
    cells = defaultdict(list)
    for r in results:
        cells[(r.spec.controller, getattr(r.spec, "protocol", "ours"), r.spec.reference, r.spec.domain)].append(
            r.metrics)
    rows = []
    for (controller, protocol, reference, domain), ms in cells.items():
        def mean(key, ms=ms):
            values = [m[key] for m in ms if key in m and math.isfinite(m[key])]
            return float(np.mean(values)) if values else math.nan

        def pooled(key, ms=ms):
            values = [m[key] for m in ms if key in m]
            return float(np.max(values)) if values else math.nan

        def median(key, ms=ms):
            values = [m[key] for m in ms if key in m and math.isfinite(m[key])]
            return float(np.median(values)) if values else math.nan

        survivors = [m for m in ms if not m["drop"]]

        def recovered_mean(key, survivors=survivors):
            """The survivors' mean recovery; inf when one of them did not recover."""
            if all(math.isfinite(m.get(key, 0.0)) for m in survivors):
                return mean(key, survivors)
            return math.inf

        rows.append({
            "controller": controller, "protocol": protocol, "reference": reference, "domain": domain,
            "set": domain_set(domain), "episodes": len(ms),
            "drop_rate": float(np.mean([m["drop"] for m in ms])),
            "rmse_steady_mm": 1e3 * mean("rmse_steady_m", survivors) if survivors else math.nan,
            # settling and push recovery: a survivor that never settled counts as inf (worst)
            "settle_s": pooled("settle_s", survivors) if survivors and any(
                not math.isfinite(m["settle_s"]) for m in survivors) else mean("settle_s", survivors),
            "push_recover_s": recovered_mean("push_recover_s"),
            "push_recover_max_s": pooled("push_recover_max_s", survivors),
            **push_counts(ms),
            # force steps (on, change, off): recovery as the pushes', the error left under each
            # step (its worst) as the mean over the survivors
            "step_recover_s": recovered_mean("step_recover_s"),
            "step_recover_max_s": pooled("step_recover_max_s", survivors),
            **{key: float(sum(m.get(key, 0.0) for m in ms)) for key in ("steps", "steps_unrecovered")},
            "step_steady_mm": 1e3 * mean("step_steady_m", survivors),
            "engaged_pct": 100.0 * mean("engaged_frac"),
            "rmse_mm": 1e3 * mean("rmse_m"),
            "rmse_release_mm": 1e3 * mean("rmse_release_m"),
            "peak_tilt_deg": math.degrees(pooled("peak_tilt_rad")),
            "smoothness_rad_s": mean("smoothness_rad_s"),
            "latency_ms": 1e3 * mean("latency_s"),
            # wall-clock times: median over episodes of each episode's percentile (machine load
            # from other work shows up as single bad episodes; the max is in the CSV of episodes)
            "tick_p99_us": median("tick_p99_us"),
            "qp_p50_us": median("qp_p50_us"),
            "qp_p99_us": median("qp_p99_us"),
            "qp_p99_worst_us": pooled("qp_p99_us"),
            "qp_fallbacks": float(sum(m.get("qp_fallbacks", 0.0) for m in ms)),
        })
    return sort_rows(rows)


SET_TITLES = {"tuning": "tuning set: the defaults are chosen on these domains",
              "held_out": "held-out set: reported, never tuned on"}


def row_set(row) -> str:
    """The row's domain set ('tuning', 'held_out'; '' for a domain of neither), from the row
    or, for a CSV without the column, from the domain."""
    return row.get("set") or domain_set(row["domain"])


def format_table(rows) -> str:
    """The headline table (our protocol: error after 5 s, settling, drops, push recovery and,
    where a domain has force steps, step recovery and the error left under each step), in
    two sections, the tuning set's and the held-out set's, each closed by one summary line
    per controller; for rows of the reference protocol, its own table beside the published
    figures."""
    ours = [r for r in rows if r["protocol"] != "reference"]
    theirs = [r for r in rows if r["protocol"] == "reference"]
    width = max([13] + [len(r["domain"]) for r in rows])
    lines = []
    if ours:
        with_steps = any(math.isfinite(r.get("steps", math.nan)) and r.get("steps") for r in ours)
        step_head = (f" {'step':>6} {'step':>6}", f" {'max s':>6} {'ss mm':>6}") if with_steps else ("", "")
        lines += [
            f"{'controller':10} {'reference':12} {'domain':{width}} {'n':>3} {'drop':>5} {'RMSE>5s':>8} "
            f"{'settle':>7} {'push':>6} {'push':>6} {'push':>7}{step_head[0]} {'engaged':>7} {'RMSE':>7} {'peak':>6} "
            f"{'du/dt':>6} {'lat':>6} {'QP p50':>7} {'QP p99':>7}",
            f"{'':10} {'':12} {'':{width}} {'':>3} {'%':>5} {'mm':>8} {'s':>7} {'rec s':>6} {'max s':>6} "
            f"{'>1 s':>7}{step_head[1]} {'%':>7} {'all mm':>7} {'deg':>6} {'rad/s':>6} {'ms':>6} {'us':>7} {'us':>7}"]
        order = list(SET_TITLES)
        sets = sorted({row_set(r) for r in ours}, key=lambda k: (order.index(k) if k in order else len(order), k))
        for key in sets:
            section = [r for r in ours if row_set(r) == key]
            lines.append(f"-- {SET_TITLES.get(key, 'other domains')}")
            for r in section:
                steps = (f" {_fix(r.get('step_recover_max_s', math.nan), 2):>6} "
                         f"{_fix(r.get('step_steady_mm', math.nan), 1):>6}") if with_steps else ""
                lines.append(
                    f"{r['controller']:10} {r['reference']:12} {r['domain']:{width}} {r['episodes']:>3} "
                    f"{100 * r['drop_rate']:>5.0f} {r['rmse_steady_mm']:>8.1f} {r['settle_s']:>7.2f} "
                    f"{_fix(r['push_recover_s'], 2):>6} {_fix(r['push_recover_max_s'], 2):>6} {late_pushes(r):>7}"
                    f"{steps} {r['engaged_pct']:>7.1f} "
                    f"{r['rmse_mm']:>7.1f} {r['peak_tilt_deg']:>6.1f} {r['smoothness_rad_s']:>6.2f} "
                    f"{r['latency_ms']:>6.0f} {_num(r['qp_p50_us']):>7} {_num(r['qp_p99_us']):>7}")
            lines += [summary_line(key, controller, [r for r in section if r["controller"] == controller])
                      for controller in dict.fromkeys(r["controller"] for r in section)]
    if theirs:
        if lines:
            lines.append("")
        lines += ["reference system's protocol: released 0-2 cm off centre at rest, 20 s, RMSE at 30 Hz from the "
                  "release over the steps before a drop",
                  f"{'controller':10} {'reference':12} {'domain':{width}} {'n':>3} {'drop':>5} {'RMSE':>7}  "
                  f"reference system's PID",
                  f"{'':10} {'':12} {'':{width}} {'':>3} {'%':>5} {'mm':>7}"]
        for r in theirs:
            lines.append(f"{r['controller']:10} {r['reference']:12} {r['domain']:{width}} {r['episodes']:>3} "
                         f"{100 * r['drop_rate']:>5.0f} {r['rmse_release_mm']:>7.1f}  "
                         f"{REFERENCE_FIGURES.get(r['domain'], '')}")
    return "\n".join(lines)


def summarise(rows) -> Dict[str, float]:
    """One controller's figures over a set's cells: episodes and drops (all cells), the mean
    and the worst cell of the RMSE after 5 s, the worst push and step recovery, late pushes
    and steps not recovered before the next."""
    episodes = sum(r["episodes"] for r in rows)
    drops = sum(r["drop_rate"] * r["episodes"] for r in rows)
    rmse = [(r["rmse_steady_mm"], r) for r in rows if math.isfinite(r["rmse_steady_mm"])]
    worst = max(rmse, key=lambda v: v[0]) if rmse else (math.nan, None)

    def worst_of(key):
        values = [r[key] for r in rows if key in r and not math.isnan(r[key])]
        return max(values) if values else math.nan

    return {"cells": len(rows), "episodes": episodes, "drops": drops,
            "rmse_steady_mean_mm": float(np.mean([v for v, _ in rmse])) if rmse else math.nan,
            "rmse_steady_worst_mm": worst[0],
            "rmse_steady_worst_cell": f"{worst[1]['reference']}/{worst[1]['domain']}" if worst[1] else "-",
            "push_recover_max_s": worst_of("push_recover_max_s"), "step_recover_max_s": worst_of("step_recover_max_s"),
            **{key: float(sum(r.get(key, 0.0) for r in rows if math.isfinite(r.get(key, 0.0))))
               for key in ("pushes", "pushes_late", "steps", "steps_unrecovered")}}


def summary_line(key: str, controller: str, rows) -> str:
    """`summarise` as one line of the table."""
    s = summarise(rows)
    pct = 100.0 * s["drops"] / s["episodes"] if s["episodes"] else math.nan
    text = (f"   {key or 'other'} {controller}: {s['cells']} cells, {s['episodes']} episodes, drops {s['drops']:.0f} "
            f"({pct:.0f} %), RMSE>5s mean {s['rmse_steady_mean_mm']:.1f} mm, worst {s['rmse_steady_worst_mm']:.1f} mm "
            f"({s['rmse_steady_worst_cell']})")
    if s["pushes"]:
        text += f", pushes late {s['pushes_late']:.0f}/{s['pushes']:.0f}, worst {_fix(s['push_recover_max_s'], 2)} s"
    if s["steps"]:
        text += (f", steps not back within 5 mm {s['steps_unrecovered']:.0f}/{s['steps']:.0f}, "
                 f"worst {_fix(s['step_recover_max_s'], 2)} s")
    return text


def push_counts(metrics) -> Dict[str, float]:
    """Pushes and late pushes summed over episodes' metrics: every push of every episode (a
    dropped episode's last push never recovered, so it counts as late)."""
    return {key: float(sum(m.get(key, 0.0) for m in metrics)) for key in ("pushes", "pushes_late")}


def late_pushes(row) -> str:
    """'late/all' pushes of a row ('-' without pushes, or from a CSV without the count)."""
    pushes = row.get("pushes", math.nan)
    if not pushes or not math.isfinite(pushes):
        return "-"
    return f"{row['pushes_late']:.0f}/{pushes:.0f}"


def _fix(v, digits: int) -> str:
    if isinstance(v, float) and math.isnan(v):
        return "-"
    return "inf" if not math.isfinite(v) else f"{v:.{digits}f}"


def _num(v) -> str:
    return "-" if not math.isfinite(v) else f"{v:.0f}"


def write_csv(rows, path: Path, columns=COLUMNS) -> None:
    """Cell rows (COLUMNS), or episode rows with columns=EPISODE_COLUMNS."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        for r in rows:
            writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})


def read_csv(path: Path) -> List[Dict[str, float]]:
    """Rows written by write_csv (numbers back as floats, the episode count and seed as int)."""
    with Path(path).open(newline="") as f:
        rows = []
        for raw in csv.DictReader(f):
            row = {k: (v if k in TEXT_COLUMNS else float(v) if v != "" else math.nan) for k, v in raw.items()}
            for key in ("episodes", "seed"):
                if key in row:
                    row[key] = int(row[key])
            rows.append(row)
    return rows


def sort_rows(rows) -> List[Dict[str, float]]:
    return sorted(rows, key=lambda r: (r["protocol"] != "ours", r["reference"], r["domain"], r["controller"]))


def plot(rows, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in rows if r["protocol"] != "reference"] or rows
    references = sorted({r["reference"] for r in rows})
    domains = list(dict.fromkeys(r["domain"] for r in rows))
    controllers = sorted({r["controller"] for r in rows})
    fig, axes = plt.subplots(len(references), 1, figsize=(max(6, 1.2 * len(domains) + 2), 3 * len(references)),
                             squeeze=False)
    width = 0.8 / max(1, len(controllers))
    for ax, reference in zip(axes[:, 0], references, strict=True):
        for i, controller in enumerate(controllers):
            values = []
            for d in domains:
                cell = [r for r in rows if r["reference"] == reference and r["domain"] == d
                        and r["controller"] == controller]
                values.append(cell[0]["rmse_steady_mm"] if cell else np.nan)
            x = np.arange(len(domains)) + i * width
            ax.bar(x, values, width, label=controller)
            for xi, d in zip(x, domains, strict=True):
                cell = [r for r in rows if r["reference"] == reference and r["domain"] == d
                        and r["controller"] == controller]
                if cell and cell[0]["drop_rate"] > 0:
                    ax.text(xi, 1, f"{100 * cell[0]['drop_rate']:.0f}% drop", rotation=90, fontsize=7)
        ax.axhline(3.0, color="k", lw=0.8, ls="--")
        ax.set_xticks(np.arange(len(domains)) + width * (len(controllers) - 1) / 2, domains, rotation=20,
                      fontsize=8)
        ax.set_ylabel("RMSE after 5 s [mm]")
        ax.set_title(f"reference: {reference} (dashed: 3 mm goal)")
        ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
