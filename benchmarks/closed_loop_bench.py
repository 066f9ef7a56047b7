#!/usr/bin/env python3
"""Closed-loop benchmark: domains x references x controllers x seeded episodes.

Lock-stepped (simulated time), so the numbers do not depend on machine load. Prints the
table (headline: RMSE after 5 s, settling time, drops, push recovery; with force steps, the
worst step's recovery and the error left under a step) and writes
<out>/closed_loop.csv, <out>/closed_loop_episodes.csv (one row per episode) and
<out>/closed_loop.png. With the PID among the controllers (--baseline), every other one is
also compared with it seed by seed: the mean difference, its 95 % interval and a verdict
(below, above, or a tie the seeds decide). With --protocol both, every cell is also
run with the reference system's own protocol (released 0-2 cm off centre, 20 s, RMSE at
30 Hz from the release before a drop) and printed beside its published figures.

Domains come in two sets (ball_balance/sim/config.py DOMAIN_SETS), printed as two sections,
each closed by a summary line per controller (cells, drops, mean and worst RMSE after 5 s,
worst recoveries), with a `set` column in the CSVs. The rule: defaults (controller gains,
tracker settings, training ranges) are chosen on the tuning set only (`--domains tuning`:
the 17 domains standard ... hand_3); the held-out set (`--domains held_out`: force steps of
1, 2, 3 degrees equivalent tilt, a plate mounted 2 degrees off level, pushes at 0.3 m/s,
three combinations of faults) is reported, never tuned on. `--domains all` (the default)
runs both.

    python benchmarks/closed_loop_bench.py                       # small: 2 episodes, fast mode
    python benchmarks/closed_loop_bench.py --episodes 30         # the full docs/design.md section 7 set
    python benchmarks/closed_loop_bench.py --controllers pid,mpc,policy --domains harsh
    python benchmarks/closed_loop_bench.py --domains held_out --references stationary,circle
    python benchmarks/closed_loop_bench.py --protocol both --domains standard,high_gravity
    python benchmarks/closed_loop_bench.py --combine artifacts/bench/a artifacts/bench/b --out artifacts/bench/all
    python benchmarks/closed_loop_bench.py --mode vision --domains standard --references circle
    python benchmarks/closed_loop_bench.py --live --episodes 1 --domains standard   # the multi-process graph
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "controller_manager_py"))  # its own package folder

from ball_balance.benchmark.episode import (  # noqa: E402
    REFERENCES,
    EpisodeSpec,
    controller_schema,
    demo_spec,
    reference_protocol,
    release_point,
    run_episode,
)
from ball_balance.benchmark.report import (  # noqa: E402
    EPISODE_COLUMNS,
    aggregate,
    episode_rows,
    format_paired_table,
    format_table,
    paired_comparison,
    plot,
    read_csv,
    sort_rows,
    write_csv,
)
from ball_balance.sim.config import DOMAIN_ALIASES, DOMAIN_SETS, DOMAINS  # noqa: E402
from ball_balance.vision.config import TRACKER_SCHEMA  # noqa: E402

# domain groups for --domains
DESIGN_DOMAINS = ["standard", "slippery", "sticky", "heavy_ball", "low_gravity", "high_gravity", "noisy_vision",
                  "high_latency", "full_dr"]
DOMAIN_GROUPS = {"all": list(DOMAINS), "tuning": list(DOMAIN_SETS["tuning"]),
                 "held_out": list(DOMAIN_SETS["held_out"]), "design": DESIGN_DOMAINS,
                 "harsh": ["noise_5mm", "latency_200ms", "low_gravity", "high_gravity", "extreme_dr"],
                 "disturbances": ["solid_ball", "pushes"], "hands": ["hand_1", "hand_2", "hand_3"]}


def names(text: str, known, what: str, groups=None) -> list:
    """A comma- (or space-) separated list of names, groups expanded; unknown names refused."""
    out = []
    for name in text.replace(",", " ").split():
        expanded = (groups or {}).get(name, [name])
        for item in expanded:
            if known is not None and item not in known:
                raise SystemExit(f"unknown {what} '{item}': expected one of {sorted(known)}"
                                 + (f" or a group {sorted(groups)}" if groups else ""))
            if item not in out:
                out.append(item)
    return out


def known_controllers():
    """Controllers the control pipeline declares (CONTROLLERS), else None (any name; the
    pipeline refuses one it does not know)."""
    from ball_balance.control import pipeline

    found = getattr(pipeline, "CONTROLLERS", None)
    return set(found) if found else None


def run_live(spec: EpisodeSpec, out: Path):
    """One episode of the real graph: sim_balance.sh with the same release rule, reference and domain."""
    import os
    import subprocess

    import numpy as np

    from ball_balance.benchmark.episode import REFERENCES, EpisodeResult

    x, y = release_point(spec, np.random.default_rng(spec.seed + 7919))   # the lock-step episodes' rule
    ref = REFERENCES[spec.reference]
    folder = out / "live" / f"{spec.controller}_{spec.reference}_{spec.domain}_{spec.seed}"
    cmd = [str(ROOT / "scripts" / "sim_balance.sh"), "--controller", spec.controller, "--ball", f"{x:.4f}", f"{y:.4f}",
           "--domain", spec.domain, "--seed", str(spec.seed), "--duration", str(spec.duration_s),
           "--out", str(folder), "--reference", ref["reference_kind"]]
    if "reference_radius_m" in ref:
        cmd += ["--radius", str(ref["reference_radius_m"]), "--period", str(ref["reference_period_s"])]
    if "reference_csv_path" in ref:
        cmd += ["--param", f"reference_csv_path:={ref['reference_csv_path']}"]
    for name, value in spec.overrides:
        cmd += ["--param", f"{name}:={value}"]
    env = dict(os.environ)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=20 * spec.duration_s)
    metrics = {"drop": 1.0}
    path = folder / "metrics.txt"
    if path.exists():
        metrics = {k: float(v) for k, v in (line.split(": ") for line in path.read_text().splitlines())}
    return EpisodeResult(spec, metrics)


EPISODE_FILE = "closed_loop_episodes.csv"


def report(rows, episodes, baseline: str, out: Path) -> None:
    """Print the table (and the paired comparison with the baseline), write the CSVs and the plot."""
    print(format_table(rows))
    paired = paired_comparison(episodes, baseline) if any(e["controller"] == baseline for e in episodes) else []
    if paired:
        print()
        print(format_paired_table(paired))
    write_csv(rows, out / "closed_loop.csv")
    if episodes:
        write_csv(episodes, out / EPISODE_FILE, EPISODE_COLUMNS)
    plot(rows, out / "closed_loop.png")
    print(f"\nwrote {out / 'closed_loop.csv'}, {out / EPISODE_FILE} and {out / 'closed_loop.png'}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--controllers", nargs="+", default=["pid,mpc"],
                        help="comma-separated controllers the control pipeline knows (pid, mpc, policy, ...)")
    parser.add_argument("--domains", nargs="+", default=["all"],
                        help=f"comma-separated domains or groups {sorted(DOMAIN_GROUPS)}: "
                             f"{', '.join(list(DOMAINS) + list(DOMAIN_ALIASES))}")
    parser.add_argument("--references", nargs="+", default=[",".join(REFERENCES)],
                        help=f"comma-separated: {', '.join(REFERENCES)}")
    parser.add_argument("--protocol", default="ours", choices=["ours", "reference", "both"],
                        help="ours: released 5-10 cm off centre, headline RMSE after 5 s; reference: the reference "
                             "system's (0-2 cm, 20 s, RMSE from the release); both: each cell twice")
    parser.add_argument("--episodes", type=int, default=2, help="seeded episodes per cell (design: 30)")
    parser.add_argument("--duration", type=float, default=20.0, help="episode length [s]")
    parser.add_argument("--mode", default="fast", choices=["fast", "vision", "truth"],
                        help="fast: sim truth + noise into the tracker's Kalman; vision: render + full tracker")
    parser.add_argument("--seed", type=int, default=0, help="first seed")
    parser.add_argument("--out", default=str(ROOT / "artifacts" / "bench"), help="output folder")
    parser.add_argument("--live", action="store_true",
                        help="run the live multi-process graph (scripts/sim_balance.sh) instead: wall-clock, slow")
    parser.add_argument("--demo", action="store_true",
                        help="only the scenario of scripts/run_demo.sh (release at (0.08, -0.05) m, circle after "
                             "6 s, camera 60 Hz, vision mode, 30 s) for --controllers, --domains and --seed")
    parser.add_argument("--baseline", default="pid",
                        help="the controller the others are compared with on the same seeds (default: pid)")
    parser.add_argument("--tracker-param", action="append", default=[], metavar="NAME:=VALUE",
                        help="a tracker parameter over config/ball_tracker.yaml, e.g. "
                             "disturbance_time_constant_s:=1.0 (repeatable; fast and vision modes)")
    parser.add_argument("--controller-param", action="append", default=[], metavar="NAME:=VALUE",
                        help="a controller parameter over the defaults, e.g. ki:=0.0 (repeatable)")
    parser.add_argument("--combine", nargs="+", metavar="DIR",
                        help="print one table from the closed_loop.csv of earlier runs (e.g. run in parallel) "
                             "and write it to --out; runs nothing")
    args = parser.parse_args(argv)
    out = Path(args.out)
    if args.combine:
        rows = sort_rows([row for folder in args.combine for row in read_csv(Path(folder) / "closed_loop.csv")])
        episodes = [row for folder in args.combine if (Path(folder) / EPISODE_FILE).exists()
                    for row in read_csv(Path(folder) / EPISODE_FILE)]
        report(rows, episodes, args.baseline, out)
        return 0
    controllers = names(" ".join(args.controllers), known_controllers(), "controller")
    domains = names(" ".join(args.domains), set(DOMAINS) | set(DOMAIN_ALIASES), "domain", DOMAIN_GROUPS)
    references = names(" ".join(args.references), set(REFERENCES), "reference")
    protocols = ["ours", "reference"] if args.protocol == "both" else [args.protocol]

    if args.demo:
        references, protocols = ["circle"], ["demo"]
    cells = [(c, r, d, p) for p in protocols for r in references for d in domains for c in controllers]
    total = len(cells) * args.episodes
    shown = demo_spec(controllers[0]) if args.demo else EpisodeSpec(duration_s=args.duration, mode=args.mode)
    print(f"closed-loop benchmark: {len(cells)} cells x {args.episodes} episodes = {total} episodes of "
          f"{shown.duration_s:.0f} s, mode {shown.mode}", flush=True)
    tracker_params = tuple(name_value(text, "--tracker-param") for text in args.tracker_param)
    controller_params = tuple(name_value(text, "--controller-param") for text in args.controller_param)
    check_names(tracker_params, TRACKER_SCHEMA, "--tracker-param", "the tracker")
    for controller in controllers:
        check_names(controller_params, controller_schema(controller), "--controller-param", controller)
    results = []
    t_start = time.monotonic()
    for i, (controller, reference, domain, protocol) in enumerate(cells):
        for k in range(args.episodes):
            spec = EpisodeSpec(controller=controller, domain=domain, reference=reference, seed=args.seed + k,
                               duration_s=args.duration, mode=args.mode)
            if protocol == "reference":
                spec = reference_protocol(spec)
            elif protocol == "demo":
                spec = demo_spec(controller, domain, args.seed + k)
            spec = dataclasses.replace(spec, tracker_overrides=tracker_params,
                                       overrides=spec.overrides + controller_params)
            results.append(run_live(spec, Path(args.out)) if args.live else run_episode(spec))
        done = (i + 1) * args.episodes
        print(f"  [{done}/{total}] {controller} {protocol} {reference} {domain}: "
              f"drops {sum(r.metrics['drop'] for r in results[-args.episodes:]):.0f}, "
              f"{time.monotonic() - t_start:.0f} s elapsed", flush=True)
    print()
    report(aggregate(results), episode_rows(results), args.baseline, out)
    return 0


def check_names(params, schema, option: str, owner: str) -> None:
    known = {p.name for p in schema}
    unknown = [name for name, _ in params if name not in known]
    if unknown:
        raise SystemExit(f"{option}: {', '.join(unknown)} is not a parameter of {owner} (docs/parameters.md)")


def name_value(text: str, option: str):
    """("name", value) from "name:=value", the value read as YAML would read it (a number, a bool)."""
    name, sep, value = text.partition(":=")
    if not sep or not name:
        raise SystemExit(f"{option} {text!r}: expected NAME:=VALUE")
    import yaml
    return name, yaml.safe_load(value)


if __name__ == "__main__":
    sys.exit(main())
