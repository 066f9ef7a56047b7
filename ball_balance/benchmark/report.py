"""Aggregate episodes into a table (stdout), a CSV and a bar plot."""
from __future__ import annotations

import csv
import math
from collections import defaultdict
from pathlib import Path
from typing import Dict, List

import numpy as np

# DESIGN.md section 7: the reference system's PID (RMSE mm, drop rate), where stated
REFERENCE_FIGURES = {"standard": "34 mm", "high_gravity": "117 mm", "*": "34-117 mm, drops 0-70 %"}

COLUMNS = ("controller", "reference", "domain", "episodes", "drop_rate", "rmse_mm", "rmse_steady_mm",
           "settle_s", "peak_tilt_deg", "smoothness_rad_s", "latency_ms", "tick_p99_us", "qp_p50_us",
           "qp_p99_us", "qp_p99_worst_us", "qp_fallbacks")


def aggregate(results) -> List[Dict[str, float]]:
    cells = defaultdict(list)
    for r in results:
        cells[(r.spec.controller, r.spec.reference, r.spec.domain)].append(r.metrics)
    rows = []
    for (controller, reference, domain), ms in cells.items():
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
        rows.append({
            "controller": controller, "reference": reference, "domain": domain, "episodes": len(ms),
            "drop_rate": float(np.mean([m["drop"] for m in ms])),
            "rmse_mm": 1e3 * mean("rmse_m"),
            "rmse_steady_mm": 1e3 * mean("rmse_steady_m", survivors) if survivors else math.nan,
            "settle_s": mean("settle_s", survivors) if survivors else math.nan,
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
    rows.sort(key=lambda r: (r["reference"], r["domain"], r["controller"]))
    return rows


def format_table(rows) -> str:
    head = (f"{'controller':10} {'reference':12} {'domain':13} {'n':>3} {'drop':>5} {'RMSE':>7} {'RMSE>5s':>8} "
            f"{'settle':>7} {'peak':>6} {'du/dt':>6} {'lat':>6} {'QP p50':>7} {'QP p99':>7}  reference PID")
    units = (f"{'':10} {'':12} {'':13} {'':>3} {'%':>5} {'mm':>7} {'mm':>8} {'s':>7} {'deg':>6} {'rad/s':>6} "
             f"{'ms':>6} {'us':>7} {'us':>7}")
    lines = [head, units]
    for r in rows:
        ref = REFERENCE_FIGURES.get(r["domain"], "") if r["controller"] == "pid" else ""
        lines.append(
            f"{r['controller']:10} {r['reference']:12} {r['domain']:13} {r['episodes']:>3} "
            f"{100 * r['drop_rate']:>5.0f} {r['rmse_mm']:>7.1f} {r['rmse_steady_mm']:>8.1f} {r['settle_s']:>7.2f} "
            f"{r['peak_tilt_deg']:>6.1f} {r['smoothness_rad_s']:>6.2f} {r['latency_ms']:>6.0f} "
            f"{_num(r['qp_p50_us']):>7} {_num(r['qp_p99_us']):>7}  {ref}")
    return "\n".join(lines)


def _num(v) -> str:
    return "-" if not math.isfinite(v) else f"{v:.0f}"


def write_csv(rows, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        for r in rows:
            writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})


def plot(rows, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

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
                values.append(cell[0]["rmse_mm"] if cell else np.nan)
            x = np.arange(len(domains)) + i * width
            ax.bar(x, values, width, label=controller)
            for xi, d in zip(x, domains, strict=True):
                cell = [r for r in rows if r["reference"] == reference and r["domain"] == d
                        and r["controller"] == controller]
                if cell and cell[0]["drop_rate"] > 0:
                    ax.text(xi, 1, f"{100 * cell[0]['drop_rate']:.0f}% drop", rotation=90, fontsize=7)
        ax.axhline(10.0, color="k", lw=0.8, ls="--")
        ax.set_xticks(np.arange(len(domains)) + width * (len(controllers) - 1) / 2, domains, rotation=20,
                      fontsize=8)
        ax.set_ylabel("RMSE [mm]")
        ax.set_title(f"reference: {reference} (dashed: 10 mm goal)")
        ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
