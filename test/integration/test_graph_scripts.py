"""The graph scripts end when a core node dies, and stop cleanly on a second Ctrl-C."""
import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest

from harness import ROOT

pytestmark = [pytest.mark.integration, pytest.mark.slow]


def start_graph(launcher, *args):
    return launcher.start([str(ROOT / "scripts" / "sim_balance.sh"), "--truth-fed", *args], name="sim_balance")


def session_pids(process, pattern: str):
    found = subprocess.run(["pgrep", "-s", str(process.popen.pid), "-f", pattern], capture_output=True, text=True)
    return [int(p) for p in found.stdout.split()]


def wait_for(condition, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"timed out after {timeout:.0f} s waiting for {what}"
        time.sleep(0.2)


def graph_logs(output: str) -> str:
    match = re.search(r"logs in (/tmp/ball_balance_graph\.\w+)", output)
    return "".join(p.read_text(errors="replace") for p in Path(match.group(1)).glob("*.log")) if match else ""


def test_sim_balance_with_a_duration_ends_when_the_controller_manager_dies(launcher):
    graph = start_graph(launcher, "--duration", "300")
    wait_for(lambda: "[monitor] t" in graph.output(), 120, "the monitor's first progress line")
    (manager,) = session_pids(graph, "ros2_control_node --ros-args")
    os.kill(manager, signal.SIGKILL)
    assert graph.wait(timeout=60) == 3, graph.output()
    assert "sim_balance.sh: sim exited; stopping the graph" in graph.output()
    # the killed manager's camera renderer (a child of the manager, not of the script) sees its
    # pipe close and shuts its DDS participant down on its own: on a loaded machine that can
    # outlast the script by a moment, so its end is awaited with a deadline
    wait_for(lambda: session_pids(graph, "ball_balance") == [], 20, "the graph's processes to end")


def test_a_second_ctrl_c_stops_the_graph_without_a_traceback(launcher):
    graph = start_graph(launcher)
    wait_for(lambda: "[monitor] t" in graph.output(), 120, "the monitor's first progress line")
    os.killpg(graph.popen.pid, signal.SIGINT)  # what a terminal's Ctrl-C does: the whole group
    time.sleep(0.5)  # the second Ctrl-C lands while the nodes shut down
    os.killpg(graph.popen.pid, signal.SIGINT)
    graph.wait(timeout=60)
    assert session_pids(graph, "ball_balance") == []
    logs = graph.output() + graph_logs(graph.output())
    assert "Traceback" not in logs, logs[-3000:]
