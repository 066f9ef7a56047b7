#!/usr/bin/env python3
"""Fault injection on the live simulated graph: the broken cases of faults.py replayed, one fresh
graph per case, and a table of what happened (ball kept on the plate, controller mode
changes after the fault, largest commanded tilt, fewest markers the tracker saw, what the
controller logged). Cases: see ball_balance/benchmark/faults.py.

    python benchmarks/fault_injection.py                          # PID and MPC, every case
    python benchmarks/fault_injection.py --controllers pid --cases rogue_far,kill_manager
    python benchmarks/fault_injection.py --keep-logs /tmp/faults  # the processes' logs
    python benchmarks/fault_injection.py --truth-fed              # /ball_state from the sim, no camera

Each case takes 30-60 s of wall time on 2 cores (start-up, 6 s settling on a circle r = 8 cm,
the fault, 5 s of watching). Processes run on a private ROS_DOMAIN_ID and are always stopped.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "controller_manager_py"))  # its own package folder
sys.path.insert(0, str(ROOT / "test"))   # the process launcher and graph node the tests use

from ball_balance.benchmark.faults import CASES, format_rows, graph_commands, run_case  # noqa: E402
from harness import DomainLease, Graph, Launcher  # noqa: E402


def run_one(controller: str, case: str, log_dir: Path, truth_fed: bool) -> dict:
    lease = DomainLease()
    launcher = Launcher(lease.domain_id, log_dir)
    graph = None
    try:
        processes = {name: launcher.start(cmd, name=f"{controller}_{case}_{name}")
                     for name, cmd in graph_commands(ROOT, controller, case, truth_fed=truth_fed)}
        graph = Graph(lease.domain_id, name="fault_injection")
        row = run_case(graph, case, processes["controller"].output, processes["sim"].output)
    except (TimeoutError, RuntimeError) as error:
        row = dict(case=case, kept="error", mode_flips=0, max_tilt_rad=float("nan"), min_markers="-",
                   logged=str(error)[:110])
    finally:
        if graph is not None:
            graph.close()
        launcher.stop_all()
        lease.release()
    row["controller"] = controller
    return row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--controllers", default="pid,mpc", help="comma-separated: pid, mpc")
    parser.add_argument("--cases", default=",".join(CASES), help=f"comma-separated: {', '.join(CASES)}")
    parser.add_argument("--keep-logs", default="", help="write the processes' logs to this folder")
    parser.add_argument("--truth-fed", action="store_true",
                        help="/ball_state from the simulation's truth plus noise (no camera, no tracker; "
                             "the hand case is skipped)")
    args = parser.parse_args(argv)
    controllers = [c for c in args.controllers.split(",") if c]
    cases = [c for c in args.cases.split(",") if c]
    for name in cases:
        if name not in CASES:
            parser.error(f"unknown case '{name}' (one of {', '.join(CASES)})")
    for name in controllers:
        if name not in ("pid", "mpc"):
            parser.error(f"unknown controller '{name}' (pid or mpc)")
    log_dir = Path(args.keep_logs) if args.keep_logs else Path(tempfile.mkdtemp(prefix="fault_injection."))
    log_dir.mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    rows = []
    load_before = os.getloadavg()[0]
    start = time.monotonic()
    for controller in controllers:
        for case in cases:
            if args.truth_fed and case == "hand_two_markers":
                continue
            rows.append(run_one(controller, case, log_dir, args.truth_fed))
            print(f"  {controller} {case}: ball kept {rows[-1]['kept']}", file=sys.stderr, flush=True)
    print(format_rows(rows))
    print(f"\nload average {load_before:.1f} at the start, {os.getloadavg()[0]:.1f} at the end; "
          f"{time.monotonic() - start:.0f} s; logs in {log_dir}")
    return 0 if all(r["kept"] in ("yes", "n/a (sim killed)") for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
