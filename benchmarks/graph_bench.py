"""What the benchmarks that run the simulated graph once per condition share (foxglove_bench.py,
live_view_bench.py): their command line, a run's private ROS domain and busy processes, the
monitor's metrics, process CPU times and the printed table."""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))
from harness import DomainLease, ros_env, stop_groups  # noqa: E402

BUSY = [sys.executable, "-c", "while True: pass"]
METRIC_HEADER = ["RTF", "drop", "RMSE>5s mm", "cam->cmd p95 ms (stamps)", "cam->cmd p95 ms (wall)"]


def arguments(doc: str, conditions, out_name: str, busy: int, argv=None):
    """(args, the conditions asked for) from the command line every such benchmark takes."""
    parser = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--conditions", default=",".join(conditions), help=f"comma-separated: {', '.join(conditions)}")
    parser.add_argument("--controller", default="pid", choices=["pid", "mpc", "policy"])
    parser.add_argument("--duration", type=float, default=30.0, help="simulated seconds per run")
    parser.add_argument("--busy", type=int, default=busy, help="extra processes each keeping a core busy")
    parser.add_argument("--out", default=str(ROOT / "artifacts" / out_name))
    args = parser.parse_args(argv)
    names = [n for n in args.conditions.split(",") if n]
    if set(names) - set(conditions):
        parser.error(f"unknown condition(s) {sorted(set(names) - set(conditions))}: expected {list(conditions)}")
    return parser, args, names


@contextmanager
def condition_run(out: Path, condition: str, busy: int):
    """(folder, environment, popens) of one condition's run: its output folder, a private ROS
    domain and `busy` busy processes; the processes put in `popens` are stopped at the end."""
    folder = out / condition
    folder.mkdir(parents=True, exist_ok=True)
    lease = DomainLease()
    busy_processes = [subprocess.Popen(BUSY) for _ in range(busy)]
    popens = []
    try:
        yield folder, ros_env(lease.domain_id), popens
    finally:
        stop_groups(popens)
        for process in busy_processes:
            process.kill()
            process.wait()
        lease.release()


def monitor_metrics(folder: Path) -> dict:
    """The graph monitor's metrics.txt in `folder` (name: value), {} without one."""
    metrics = folder / "metrics.txt"
    if not metrics.exists():
        return {}
    return {k: float(v) for k, v in (line.split(": ") for line in metrics.read_text().splitlines())}


def metric_cells(row: dict) -> list:
    """The cells of METRIC_HEADER for a run's row."""
    return [cell(row, "real_time_factor", fmt="{:.2f}"), cell(row, "drop", fmt="{:.0f}"),
            cell(row, "rmse_steady_m", 1e3), cell(row, "latency_p95_s", 1e3),
            cell(row, "latency_wall_p95_s", 1e3, "{:.0f}")]


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


def cell(row: dict, key: str, scale: float = 1.0, fmt: str = "{:.1f}") -> str:
    value = row.get(key)
    return "-" if value is None else fmt.format(value * scale)


def print_table(header, rows) -> None:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    print(" | ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)))
    print("-+-".join("-" * w for w in widths))
    for r in rows:
        print(" | ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)))


def footer(args, load_before: float, out: Path) -> str:
    return (f"{args.controller}, {args.duration:g} s of simulated time per run, {args.busy} busy process(es), "
            f"{os.cpu_count()} CPUs; load average {load_before:.1f} before, {os.getloadavg()[0]:.1f} after; "
            f"files in {out}")
