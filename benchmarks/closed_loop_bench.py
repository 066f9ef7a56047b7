#!/usr/bin/env python3
"""Closed-loop benchmark: domains x references x controllers x seeded episodes.

Lock-stepped (simulated time), so the numbers do not depend on machine load. Prints the
table and writes <out>/closed_loop.csv and <out>/closed_loop.png.

    python benchmarks/closed_loop_bench.py                       # small: 2 episodes, fast mode
    python benchmarks/closed_loop_bench.py --episodes 30         # the full DESIGN.md section 7 set
    python benchmarks/closed_loop_bench.py --mode vision --domains standard --references circle
    python benchmarks/closed_loop_bench.py --live --episodes 1 --domains standard   # the multi-process graph
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ball_balance.benchmark.episode import REFERENCES, EpisodeSpec, run_episode  # noqa: E402
from ball_balance.benchmark.report import aggregate, format_table, plot, write_csv  # noqa: E402
from ball_balance.sim.config import DOMAINS  # noqa: E402


def run_live(spec: EpisodeSpec, out: Path):
    """One episode of the real graph: sim_balance.sh with the same release rule, reference and domain."""
    import math
    import os
    import subprocess

    import numpy as np

    from ball_balance.benchmark.episode import REFERENCES, EpisodeResult

    rng = np.random.default_rng(spec.seed + 7919)   # the lock-step episodes' release rule
    radius, angle = rng.uniform(*spec.release_radius_m), rng.uniform(0, 2 * math.pi)
    ref = REFERENCES[spec.reference]
    folder = out / "live" / f"{spec.controller}_{spec.reference}_{spec.domain}_{spec.seed}"
    cmd = [str(ROOT / "scripts" / "sim_balance.sh"), "--controller", spec.controller,
           "--ball", f"{radius * math.cos(angle):.4f}", f"{radius * math.sin(angle):.4f}",
           "--domain", spec.domain, "--seed", str(spec.seed), "--duration", str(spec.duration_s),
           "--out", str(folder), "--reference", ref["reference_kind"]]
    if "reference_radius_m" in ref:
        cmd += ["--radius", str(ref["reference_radius_m"]), "--period", str(ref["reference_period_s"])]
    env = dict(os.environ)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=20 * spec.duration_s)
    metrics = {"drop": 1.0}
    path = folder / "metrics.txt"
    if path.exists():
        metrics = {k: float(v) for k, v in (line.split(": ") for line in path.read_text().splitlines())}
    return EpisodeResult(spec, metrics)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--controllers", nargs="+", default=["pid", "mpc"], choices=["pid", "mpc"])
    parser.add_argument("--domains", nargs="+", default=list(DOMAINS), choices=list(DOMAINS))
    parser.add_argument("--references", nargs="+", default=list(REFERENCES), choices=list(REFERENCES))
    parser.add_argument("--episodes", type=int, default=2, help="seeded episodes per cell (design: 30)")
    parser.add_argument("--duration", type=float, default=20.0, help="episode length [s]")
    parser.add_argument("--mode", default="fast", choices=["fast", "vision", "truth"],
                        help="fast: sim truth + noise into the tracker's Kalman; vision: render + full tracker")
    parser.add_argument("--seed", type=int, default=0, help="first seed")
    parser.add_argument("--out", default=str(ROOT / "artifacts" / "bench"), help="output folder")
    parser.add_argument("--live", action="store_true",
                        help="run the live multi-process graph (scripts/sim_balance.sh) instead: wall-clock, slow")
    args = parser.parse_args(argv)

    cells = [(c, r, d) for r in args.references for d in args.domains for c in args.controllers]
    total = len(cells) * args.episodes
    print(f"closed-loop benchmark: {len(cells)} cells x {args.episodes} episodes = {total} episodes of "
          f"{args.duration:.0f} s, mode {args.mode}", flush=True)
    results = []
    t_start = time.monotonic()
    for i, (controller, reference, domain) in enumerate(cells):
        for k in range(args.episodes):
            spec = EpisodeSpec(controller=controller, domain=domain, reference=reference, seed=args.seed + k,
                               duration_s=args.duration, mode=args.mode)
            results.append(run_live(spec, Path(args.out)) if args.live else run_episode(spec))
        done = (i + 1) * args.episodes
        print(f"  [{done}/{total}] {controller} {reference} {domain}: "
              f"drops {sum(r.metrics['drop'] for r in results[-args.episodes:]):.0f}, "
              f"{time.monotonic() - t_start:.0f} s elapsed", flush=True)
    rows = aggregate(results)
    print()
    print(format_table(rows))
    out = Path(args.out)
    write_csv(rows, out / "closed_loop.csv")
    plot(rows, out / "closed_loop.png")
    print(f"\nwrote {out / 'closed_loop.csv'} and {out / 'closed_loop.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
