#!/usr/bin/env python3
"""The main job on a slower machine: scripts/run_demo.sh's run under several loads, side by side.

Runs the demo's simulated graph (scripts/sim_balance.sh with run_demo.sh's scenario, the
rendered camera, the tracker and the controller) once per condition, then the same scenario
lock-stepped in one process (closed_loop_bench.py --demo), and prints one table: wall time,
real-time factor, drop, RMSE after 5 s, settling time and camera-to-command (stamps). With
lock-step pacing the figures must agree across the rows; only the wall time may differ.

Conditions (--conditions, comma-separated):
  quiet      nothing else started
  busy2      two busy processes (`python3 -c 'while True: pass'`) beside the graph
  pinned     the whole graph pinned to one CPU (taskset -c 0)
  pinned2    pinned to one CPU with two busy processes pinned there too
  slow3x     rendering slowed by 40 ms a frame (camera_extra_render_s), nothing else
  rt_on      SCHED_FIFO forced for the control chain (BALL_BALANCE_REALTIME=on), one busy process
  rt_off     normal scheduling forced (BALL_BALANCE_REALTIME=off), one busy process

    python benchmarks/demo_anywhere_bench.py                       # quiet,busy2,pinned; PID
    python benchmarks/demo_anywhere_bench.py --conditions rt_on,rt_off --controller mpc
    python benchmarks/demo_anywhere_bench.py --duration 15 --out artifacts/demo_anywhere
    python benchmarks/demo_anywhere_bench.py --domain force_3deg --conditions quiet,busy2

With a domain of force steps (force_1deg ... force_3deg: on at 5 s, turned at 9 s, off at 13 s)
the table also gives the worst step's recovery and the error left under it, as
offset_free_bench.py measures them: the live monitor times each step from /sim/ball_force.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "controller_manager_py"))  # its own package folder

PRIVATE_DOMAINS = range(150, 230)
BUSY = [sys.executable, "-c", "while True: pass"]
CONDITIONS = {   # name: (busy processes, pinned to CPU 0, extra environment, extra sim_balance.sh arguments)
    "quiet": (0, False, {}, []),
    "busy2": (2, False, {}, []),
    "pinned": (0, True, {}, []),
    "pinned2": (2, True, {}, []),
    "slow3x": (0, False, {}, ["--sim-param", "camera_extra_render_s=0.04"]),
    "rt_on": (1, False, {"BALL_BALANCE_REALTIME": "on"}, []),
    "rt_off": (1, False, {"BALL_BALANCE_REALTIME": "off"}, []),
}


def run_condition(name: str, controller: str, domain: str, duration_s: float, out: Path) -> dict:
    from ball_balance.benchmark.episode import REFERENCES, demo_spec

    busy, pinned, env_extra, extra = CONDITIONS[name]
    folder = out / name
    pin = ["taskset", "-c", "0"] if pinned else []
    spec = demo_spec(controller, domain, duration_s=duration_s)   # the scenario, as the lock-stepped row runs it
    reference = REFERENCES[spec.reference]
    cmd = [*pin, str(ROOT / "scripts" / "sim_balance.sh"), "--controller", controller,
           "--ball", *(str(v) for v in spec.release_xy_m), "--reference", reference["reference_kind"],
           "--radius", str(reference["reference_radius_m"]), "--period", str(reference["reference_period_s"]),
           "--domain", spec.domain, "--seed", str(spec.seed), "--duration", str(duration_s), "--out", str(folder),
           *extra]
    for param, value in spec.overrides:
        cmd += ["--param", f"{param}:={value}"]
    # a ROS domain of its own: another graph on the machine must not answer for this one
    env = dict(os.environ, ROS_DOMAIN_ID=str(PRIVATE_DOMAINS.start + os.getpid() % len(PRIVATE_DOMAINS)),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", **env_extra)
    loads = [subprocess.Popen([*pin, *BUSY]) for _ in range(busy)]
    start = time.monotonic()
    try:
        with open(out / f"{name}.log", "w") as log:
            code = subprocess.run(cmd, env=env, stdout=log, stderr=subprocess.STDOUT,
                                  timeout=120 * duration_s).returncode
    except subprocess.TimeoutExpired:
        code = "timeout"
    finally:
        for load in loads:
            load.kill()
    wall_s = time.monotonic() - start
    metrics = {}
    path = folder / "metrics.txt"
    if path.exists():
        metrics = {k: float(v) for k, v in (line.split(": ") for line in path.read_text().splitlines())}
    return {"condition": name, "exit": code, "wall_s": wall_s, **metrics}


def lockstepped(controller: str, domain: str, duration_s: float) -> dict:
    from ball_balance.benchmark.episode import demo_spec, run_episode

    start = time.monotonic()
    result = run_episode(demo_spec(controller, domain, duration_s=duration_s))
    return {"condition": "closed_loop_bench --demo", "exit": 0, "wall_s": time.monotonic() - start,
            **result.metrics}


def cell(row: dict, key: str, scale: float = 1.0, fmt: str = "{:.1f}") -> str:
    value = row.get(key)
    return "-" if value is None else fmt.format(value * scale)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--conditions", default="quiet,busy2,pinned", help=f"comma-separated: {', '.join(CONDITIONS)}")
    parser.add_argument("--controller", default="pid", choices=["pid", "mpc", "policy"])
    parser.add_argument("--domain", default="standard", help="the simulation's domain (run_demo.sh: standard)")
    parser.add_argument("--duration", type=float, default=30.0, help="simulated seconds (run_demo.sh: 30)")
    parser.add_argument("--out", default=str(ROOT / "artifacts" / "demo_anywhere"))
    args = parser.parse_args(argv)
    names = [n for n in args.conditions.split(",") if n]
    unknown = [n for n in names if n not in CONDITIONS]
    if unknown:
        parser.error(f"unknown condition(s) {unknown}: expected {list(CONDITIONS)}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    load_before = os.getloadavg()[0]
    rows = []
    for name in names:
        rows.append(run_condition(name, args.controller, args.domain, args.duration, out))
        print(f"  {name}: exit {rows[-1]['exit']}, {rows[-1]['wall_s']:.0f} s", flush=True)
    rows.append(lockstepped(args.controller, args.domain, args.duration))
    header = ["condition", "exit", "wall s", "RTF", "drop", "RMSE>5s mm", "settle s", "cam->cmd mean ms",
              "cam->cmd p95 ms"]
    table = [[r["condition"], str(r["exit"]), f"{r['wall_s']:.0f}", cell(r, "real_time_factor", fmt="{:.2f}"),
              cell(r, "drop", fmt="{:.0f}"), cell(r, "rmse_steady_m", 1e3), cell(r, "settle_s", fmt="{:.2f}"),
              cell(r, "latency_s", 1e3), cell(r, "latency_p95_s", 1e3)] for r in rows]
    if any(r.get("steps") for r in rows):
        header += ["steps", "worst step s", "left mm"]
        for r, line in zip(rows, table, strict=True):
            line += [cell(r, "steps", fmt="{:.0f}"), cell(r, "step_recover_max_s", fmt="{:.2f}"),
                     cell(r, "step_steady_m", 1e3, fmt="{:.2f}")]
    widths = [max(len(h), *(len(row[i]) for row in table)) for i, h in enumerate(header)]
    print()
    print(" | ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)))
    print("-+-".join("-" * w for w in widths))
    for row in table:
        print(" | ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)))
    print(f"\n{args.controller}, {args.domain}, {args.duration:g} s of simulated time, {os.cpu_count()} CPUs; "
          f"load average {load_before:.1f} before, {os.getloadavg()[0]:.1f} after; graphs' files in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
