#!/usr/bin/env python3
"""Control variants side by side: the same seeded, lock-stepped closed-loop episodes
(ball_balance.benchmark.run_episode) run with different controller parameter overrides, one
table. For judging a control change (adaptation, braking, gains) before it becomes a default.

    python benchmarks/control_variants_bench.py --domains low_gravity,pushes --episodes 5 \\
        --variant off: --variant adapt:adapt_plant_gain=true,adapt_disturbance=true
    python benchmarks/control_variants_bench.py --references circle --domains standard --lose 8 3 \\
        --variant hold:brake_on_loss_s=0 --variant brake:      # tracking lost on a circle

A variant is NAME:param=value,param=value (values parsed as YAML: true, 0.5, [0, 0]); an empty
list runs the defaults (config/<controller>.yaml over the schema). A parameter named
tracker.NAME is the tracker's (over config/ball_tracker.yaml), e.g.
`--variant fixed:tracker.use_plate_cmd=false,tracker.adaptive_meas_noise=false`, and one named
episode.NAME a field of the episode's spec (ball_balance.benchmark.EpisodeSpec), e.g.
`--variant nodes:episode.command_write_hz=0` (joint targets as the balance nodes send them). Per cell: drops, RMSE after
5 s (mean and worst episode), settling time (worst), push recovery (mean, worst, pushes over 1 s) and tick p50.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import re
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "controller_manager_py"))  # its own package folder

from closed_loop_bench import DOMAIN_GROUPS, names  # noqa: E402

from ball_balance.benchmark.episode import EpisodeSpec, Occlusion, run_episode  # noqa: E402
from ball_balance.benchmark.report import late_pushes, push_counts  # noqa: E402
from ball_balance.sim.config import DOMAIN_ALIASES, DOMAINS  # noqa: E402


def parse_variant(text: str):
    """NAME:param=value,... -> (name, controller overrides, tracker overrides, episode spec fields)."""
    name, _, body = text.partition(":")
    overrides, tracker, episode = [], [], {}
    # commas inside [...] belong to a list value (input_gain_bounds=[0.3,2.5])
    for item in filter(None, (part.strip() for part in re.split(r",(?![^\[]*\])", body))):
        key, sep, value = item.partition("=")
        if not sep:
            raise SystemExit(f"variant '{text}': '{item}' is not param=value")
        key = key.strip()
        if key.startswith("tracker."):
            tracker.append((key[len("tracker."):], yaml.safe_load(value)))
        elif key.startswith("episode."):
            field = key[len("episode."):]
            if field not in {f.name for f in dataclasses.fields(EpisodeSpec)}:
                raise SystemExit(f"variant '{text}': EpisodeSpec has no field '{field}'")
            episode[field] = yaml.safe_load(value)
        else:
            overrides.append((key, yaml.safe_load(value)))
    return name or "default", tuple(overrides), tuple(tracker), episode


def _finite(values):
    return [v for v in values if math.isfinite(v)]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--controllers", default="pid,mpc")
    parser.add_argument("--domains", default="standard,low_gravity,full_dr",
                        help=f"comma-separated domains or groups {sorted(DOMAIN_GROUPS)}")
    parser.add_argument("--references", default="stationary,circle")
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--duration", type=float, default=15.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--mode", default="fast", choices=["fast", "vision", "truth"])
    parser.add_argument("--release-speed", type=float, default=0.0,
                        help="release the ball rolling at up to this speed [m/s] (seeded direction)")
    parser.add_argument("--lose", type=float, nargs=2, metavar=("T_S", "FOR_S"),
                        help="hide all four markers at T_S for FOR_S seconds (tracking lost: braking, return home)")
    parser.add_argument("--variant", action="append", default=[], help="NAME:param=value,... (repeatable)")
    args = parser.parse_args(argv)
    variants = [parse_variant(v) for v in (args.variant or ["default:"])]
    events = (Occlusion(args.lose[0], args.lose[1], (0, 1, 2, 3)),) if args.lose else ()
    split = lambda text: [x for x in text.replace(" ", ",").split(",") if x]  # noqa: E731
    domains = names(args.domains, set(DOMAINS) | set(DOMAIN_ALIASES), "domain", DOMAIN_GROUPS)
    cells = [(c, r, d) for r in split(args.references) for d in domains for c in split(args.controllers)]
    print(f"control variants: {len(cells)} cells x {len(variants)} variants x {args.episodes} episodes of "
          f"{args.duration:.0f} s, mode {args.mode}", flush=True)
    header = (f"{'variant':<12} {'ctrl':<5} {'reference':<11} {'domain':<14} {'n':>2} {'drops':>5} "
              f"{'RMSE>5s':>7} {'worst':>6} {'settle':>6} {'push':>5} {'push':>5} {'push':>7} {'tick':>6}")
    units = f"{'':<12} {'':<5} {'':<11} {'':<14} {'':>2} {'':>5} {'mm':>7} {'mm':>6} {'s':>6} " \
            f"{'rec s':>5} {'max s':>5} {'>1 s':>7} {'p50 us':>6}"
    lines = []
    t_start = time.monotonic()
    for controller, reference, domain in cells:
        for name, overrides, tracker_overrides, episode_fields in variants:
            ms = []
            for k in range(args.episodes):
                spec = EpisodeSpec(controller=controller, domain=domain, reference=reference, seed=args.seed + k,
                                   duration_s=args.duration, mode=args.mode, overrides=overrides,
                                   tracker_overrides=tracker_overrides,
                                   release_speed_m_s=(0.0, args.release_speed), events=events, **episode_fields)
                ms.append(run_episode(spec).metrics)
            kept = [m for m in ms if not m["drop"]]
            steady = _finite([1e3 * m["rmse_steady_m"] for m in kept])
            settle = [m["settle_s"] for m in kept]
            push = [m["push_recover_s"] for m in kept if "push_recover_s" in m]
            push_max = [m["push_recover_max_s"] for m in kept if "push_recover_max_s" in m]
            late = late_pushes(push_counts(ms))
            fmt = lambda v: f"{v:.2f}" if math.isfinite(v) else "inf"  # noqa: E731
            line = (f"{name:<12} {controller:<5} {reference:<11} {domain:<14} {len(ms):>2} "
                    f"{sum(m['drop'] for m in ms):>5.0f} "
                    f"{np.mean(steady) if steady else math.nan:>7.2f} {max(steady) if steady else math.nan:>6.2f} "
                    f"{fmt(max(settle)) if settle else '-':>6} "
                    f"{(fmt(float(np.mean(push))) if push else '-'):>5} {(fmt(max(push_max)) if push_max else '-'):>5} "
                    f"{late:>7} "
                    f"{np.median([m['tick_p50_us'] for m in ms]):>6.0f}")
            lines.append(line)
            print(f"  {line}   ({time.monotonic() - t_start:.0f} s)", flush=True)
    print()
    print(header)
    print(units)
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
