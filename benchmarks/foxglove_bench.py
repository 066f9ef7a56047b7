#!/usr/bin/env python3
"""What serving the graph to Foxglove costs: ball_balance_foxglove's CPU, and the control chain's
camera-to-command latency with and without it, side by side.

Runs the simulated balancing graph (scripts/sim_balance.sh: MuJoCo arm and camera, tracker, PID,
visualizer, monitor) for --duration simulated seconds once per condition, on a private ROS domain:

  none      no Foxglove node
  idle      ball_balance_foxglove with its default topics, no client connected
  watched   the node, and a Foxglove WebSocket client (test/integration/foxglove_client, Node.js)
            subscribed to every default topic, decoding every message as a viewer does

The node's CPU is its user + system time (all threads) from the moment it has advertised
/camera/image_raw to the end of the run, over that wall time (100 % = one core). The client
is started at that moment too; its figures are its own process's. Camera-to-command is the
monitor's (metrics.txt: stamps, and the wall clock). --busy N adds processes that each keep a
core busy.

    python benchmarks/foxglove_bench.py
    python benchmarks/foxglove_bench.py --conditions none,watched --busy 1 --duration 20
"""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))
import foxglove_ws_client  # noqa: E402
from ball_balance.nodes.foxglove_node import DEFAULT_TOPICS  # noqa: E402
from harness import DomainLease, executable, ros_env, stop_groups  # noqa: E402

CONDITIONS = ("none", "idle", "watched")
BUSY = [sys.executable, "-c", "while True: pass"]
ADVERTISED = "advertised /camera/image_raw"


def process_cpu_s(pid: int) -> float:
    """User + system CPU time of one process (all its threads), s."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except FileNotFoundError:
        return float("nan")
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def wait_for_line(path: Path, text: str, popen: subprocess.Popen, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and popen.poll() is None:
        if path.exists() and text in path.read_text(errors="replace"):
            return True
        time.sleep(0.2)
    return False


def run_condition(condition: str, args, out: Path) -> dict:
    folder = out / condition
    folder.mkdir(parents=True, exist_ok=True)
    lease = DomainLease()
    env = ros_env(lease.domain_id)
    busy = [subprocess.Popen(BUSY) for _ in range(args.busy)]
    popens, row = [], {"condition": condition}
    try:
        if condition != "none":
            node_log = folder / "foxglove.log"
            with open(node_log, "wb") as log:
                node = subprocess.Popen([executable("ball_balance_foxglove"), "--ros-args", "-p", "port:=0"],
                                        env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
            popens.append(node)
        with open(folder / "graph.log", "wb") as log:
            graph = subprocess.Popen([str(ROOT / "scripts" / "sim_balance.sh"), "--controller", args.controller,
                                      "--duration", str(args.duration), "--out", str(folder)],
                                     env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        popens.append(graph)
        started, node_cpu0, client = time.monotonic(), 0.0, None
        if condition != "none":
            if not wait_for_line(node_log, ADVERTISED, node, 300):
                raise RuntimeError(f"{condition}: the node did not advertise the camera (see {node_log})")
            started, node_cpu0 = time.monotonic(), process_cpu_s(node.pid)
            if condition == "watched":
                port = re.search(r"ws://127\.0\.0\.1:(\d+)", node_log.read_text()).group(1)
                topics = [arg for topic in DEFAULT_TOPICS for arg in ("--topic", topic)]
                client_out = open(folder / "client.json", "wb")
                client = subprocess.Popen(
                    foxglove_ws_client.command(f"ws://127.0.0.1:{port}", "--watch", "100000", *topics),
                    env=dict(env, NODE_PATH=args.node_modules), stdout=client_out, stderr=subprocess.DEVNULL,
                    start_new_session=True)
                popens.append(client)
        row["exit"] = graph.wait(timeout=120 * args.duration)
        wall_s = time.monotonic() - started
        if condition != "none":
            row["node_cpu_pct"] = 100 * (process_cpu_s(node.pid) - node_cpu0) / wall_s
        if client is not None:
            row["client_cpu_pct"] = 100 * process_cpu_s(client.pid) / wall_s
            stop_groups([client])
            client_out.close()
            received = json.loads((folder / "client.json").read_text())["received"]
            row["received"], row["client_s"] = received, wall_s
        metrics = folder / "metrics.txt"
        if metrics.exists():
            row.update({k: float(v) for k, v in (line.split(": ") for line in metrics.read_text().splitlines())})
    finally:
        stop_groups(popens)
        for process in busy:
            process.kill()
            process.wait()
        lease.release()
    return row


def cell(row: dict, key: str, scale: float = 1.0, fmt: str = "{:.1f}") -> str:
    value = row.get(key)
    return "-" if value is None else fmt.format(value * scale)


def print_table(header, rows) -> None:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    print(" | ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)))
    print("-+-".join("-" * w for w in widths))
    for r in rows:
        print(" | ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--conditions", default=",".join(CONDITIONS), help=f"comma-separated: {', '.join(CONDITIONS)}")
    parser.add_argument("--controller", default="pid", choices=["pid", "mpc", "policy"])
    parser.add_argument("--duration", type=float, default=30.0, help="simulated seconds per run")
    parser.add_argument("--busy", type=int, default=0, help="extra processes each keeping a core busy")
    parser.add_argument("--out", default=str(ROOT / "artifacts" / "foxglove_bench"))
    args = parser.parse_args(argv)
    names = [n for n in args.conditions.split(",") if n]
    if set(names) - set(CONDITIONS):
        parser.error(f"unknown condition(s) {sorted(set(names) - set(CONDITIONS))}: expected {list(CONDITIONS)}")
    if "watched" in names:
        missing = foxglove_ws_client.missing_tools()
        if missing:
            parser.error(f"the watched condition needs {' and '.join(missing)} (Node.js)")
        args.node_modules = foxglove_ws_client.install()
    out = Path(args.out)
    load_before = os.getloadavg()[0]
    rows = []
    for name in names:
        rows.append(run_condition(name, args, out))
        print(f"  {name}: exit {rows[-1]['exit']}", flush=True)
    print()
    print_table(["condition", "exit", "RTF", "drop", "RMSE>5s mm", "cam->cmd p95 ms (stamps)", "cam->cmd p95 ms (wall)",
                 "node CPU %", "client CPU %"],
                [[r["condition"], str(r["exit"]), cell(r, "real_time_factor", fmt="{:.2f}"),
                  cell(r, "drop", fmt="{:.0f}"), cell(r, "rmse_steady_m", 1e3), cell(r, "latency_p95_s", 1e3),
                  cell(r, "latency_wall_p95_s", 1e3, "{:.0f}"), cell(r, "node_cpu_pct"), cell(r, "client_cpu_pct")]
                 for r in rows])
    watched = [r for r in rows if "received" in r]
    if watched:
        row = watched[0]
        print(f"\nwhat the client received in {row['client_s']:.0f} s:\n")
        print_table(["topic", "messages", "per s"],
                    [[t, str(n), f"{n / row['client_s']:.1f}"] for t, n in row["received"].items()])
    print(f"\n{args.controller}, {args.duration:g} s of simulated time per run, {args.busy} busy process(es), "
          f"{os.cpu_count()} CPUs; load average {load_before:.1f} before, {os.getloadavg()[0]:.1f} after; "
          f"files in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
