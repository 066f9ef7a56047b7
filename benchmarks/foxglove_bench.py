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

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))
from graph_bench import (  # noqa: E402
    METRIC_HEADER,
    arguments,
    cell,
    condition_run,
    footer,
    metric_cells,
    monitor_metrics,
    print_table,
    process_cpu_s,
    wait_for_line,
)

import foxglove_ws_client  # noqa: E402
from ball_balance.nodes.foxglove_node import DEFAULT_TOPICS  # noqa: E402
from harness import executable, stop_groups  # noqa: E402

CONDITIONS = ("none", "idle", "watched")
ADVERTISED = "advertised /camera/image_raw"


def run_condition(condition: str, args, out: Path) -> dict:
    row = {"condition": condition}
    with condition_run(out, condition, args.busy) as (folder, env, popens):
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
        row.update(monitor_metrics(folder))
    return row


def main(argv=None) -> int:
    parser, args, names = arguments(__doc__, CONDITIONS, "foxglove_bench", busy=0, argv=argv)
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
    print_table(["condition", "exit", *METRIC_HEADER, "node CPU %", "client CPU %"],
                [[r["condition"], str(r["exit"]), *metric_cells(r), cell(r, "node_cpu_pct"), cell(r, "client_cpu_pct")]
                 for r in rows])
    watched = [r for r in rows if "received" in r]
    if watched:
        row = watched[0]
        print(f"\nwhat the client received in {row['client_s']:.0f} s:\n")
        print_table(["topic", "messages", "per s"],
                    [[t, str(n), f"{n / row['client_s']:.1f}"] for t, n in row["received"].items()])
    print("\n" + footer(args, load_before, out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
