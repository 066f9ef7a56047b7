#!/usr/bin/env python3
"""What the live view costs the control chain: camera-to-command latency with and without a page
open, side by side, and the live view's own CPU.

Runs the simulated balancing graph (scripts/sim_balance.sh: MuJoCo arm and camera, tracker, PID,
visualizer, monitor) for --duration simulated seconds once per condition, on a private ROS domain:

  none      no live view (--no-live-view)
  idle      ball_balance_live_view running (as the scripts start it), no page connected
  open      the live view and its page open in headless Chromium (test/cdp_client.py), which
            receives the state at 10 Hz and camera frames (JPEG) at up to 15 Hz

The node's CPU is its user + system time (all threads) from the moment its address is printed
(idle) or the page is connected (open) to the end of the run, over that wall time (100 % = one
core); the browser's is the sum over its processes. Camera-to-command is the monitor's
(metrics.txt: stamps, and the wall clock). --busy N adds processes that each keep a core busy.

    python benchmarks/live_view_bench.py
    python benchmarks/live_view_bench.py --conditions none,open --busy 1 --duration 20
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))
from cdp_client import Browser  # noqa: E402
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

CONDITIONS = ("none", "idle", "open")
ANNOUNCED = "live view (open it in a browser): "


def descendants(pid: int) -> list:
    """Every process below pid (from /proc)."""
    children = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                parent = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (FileNotFoundError, IndexError, ValueError):
                continue
            children.setdefault(parent, []).append(int(entry.name))
    found, todo = [], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found


def live_view_pid(graph_pid: int) -> int:
    """The node's Python process (not the script's shell that started it)."""
    for pid in descendants(graph_pid):
        try:
            words = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except FileNotFoundError:
            continue
        if "python" in Path(words[0].decode()).name and any(w.endswith(b"/ball_balance_live_view") for w in words):
            return pid
    raise RuntimeError("no ball_balance_live_view process under the graph")


def wait_sampling(popen: subprocess.Popen, timeout_s: float, sample) -> tuple:
    """Wait for popen's exit while calling sample() twice a second (the graph's processes are
    gone once it has exited); (exit code, sample()'s last value, when it was taken)."""
    deadline, last = time.monotonic() + timeout_s, (None, time.monotonic())
    while popen.poll() is None:
        if time.monotonic() > deadline:
            raise subprocess.TimeoutExpired(popen.args, timeout_s)
        value = sample()
        if value == value:     # not nan: the processes still there
            last = (value, time.monotonic())
        time.sleep(0.5)
    return popen.returncode, last[0], last[1]


def group_cpu_s(pid: int) -> float:
    return sum(process_cpu_s(p) for p in [pid, *descendants(pid)] if Path(f"/proc/{p}").exists())


def run_condition(condition: str, args, out: Path) -> dict:
    row, browser = {"condition": condition}, None
    with condition_run(out, condition, args.busy) as (folder, env, popens):
        try:
            view = ["--no-live-view"] if condition == "none" else ["--live-view-port", "0"]
            graph_log = folder / "graph.log"
            with open(graph_log, "wb") as log:
                graph = subprocess.Popen([str(ROOT / "scripts" / "sim_balance.sh"), "--controller", args.controller,
                                          "--duration", str(args.duration), "--out", str(folder), *view],
                                         env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
            popens.append(graph)
            started, node_cpu0, node = time.monotonic(), 0.0, None
            if condition != "none":
                if not wait_for_line(graph_log, ANNOUNCED, graph, 300):
                    raise RuntimeError(f"{condition}: the live view did not start (see {graph_log})")
                url = re.search(re.escape(ANNOUNCED) + r"(\S+)", graph_log.read_text()).group(1)
                node = live_view_pid(graph.pid)
                if condition == "open":
                    browser = Browser(folder / "chromium.log")
                    browser.open(url)
                    browser.wait_for("document.getElementById('connection').textContent === 'connected'", 120.0)
                started, node_cpu0 = time.monotonic(), process_cpu_s(node)
                browser_cpu0 = group_cpu_s(browser.process.pid) if browser else 0.0
            row["exit"], node_cpu, sampled = wait_sampling(graph, 120 * args.duration,
                                                          lambda: process_cpu_s(node) if node else float("nan"))
            wall_s = time.monotonic() - started
            if node is not None and node_cpu is not None:
                row["node_cpu_pct"] = 100 * (node_cpu - node_cpu0) / (sampled - started)
            if browser is not None:
                row["browser_cpu_pct"] = 100 * (group_cpu_s(browser.process.pid) - browser_cpu0) / wall_s
                frames = browser.evaluate("parseInt(/(\\d+) sent/.exec(document.getElementById('image-info')"
                                          ".textContent)[1])")
                row["frames_per_s"] = (frames or 0) / wall_s
            row.update(monitor_metrics(folder))
        finally:
            if browser is not None:
                browser.close()
    return row


def main(argv=None) -> int:
    _, args, names = arguments(__doc__, CONDITIONS, "live_view_bench", busy=1, argv=argv)
    out = Path(args.out)
    load_before = os.getloadavg()[0]
    rows = []
    for name in names:
        rows.append(run_condition(name, args, out))
        print(f"  {name}: exit {rows[-1]['exit']}", flush=True)
    print()
    print_table(["condition", "exit", *METRIC_HEADER, "node CPU %", "browser CPU %", "frames/s"],
                [[r["condition"], str(r["exit"]), *metric_cells(r), cell(r, "node_cpu_pct"),
                  cell(r, "browser_cpu_pct"), cell(r, "frames_per_s")]
                 for r in rows])
    print("\n" + footer(args, load_before, out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
