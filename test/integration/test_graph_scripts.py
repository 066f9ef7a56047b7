"""The graph scripts end when a core node dies, and stop cleanly on a second Ctrl-C."""
import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest

from harness import ROOT, ros_env

pytestmark = [pytest.mark.integration, pytest.mark.slow]


def start_graph(launcher, *args):
    return launcher.start([str(ROOT / "scripts" / "sim_balance.sh"), "--truth-fed", *args], name="sim_balance")


def session_pids(process, pattern: str):
    found = subprocess.run(["pgrep", "-s", str(process.popen.pid), "-f", pattern], capture_output=True, text=True)
    return [int(p) for p in found.stdout.split()]


def session_table(process) -> str:
    """Every process still in the graph's session, with its parent and state (for a failure message)."""
    table = subprocess.run(["ps", "-s", str(process.popen.pid), "-o", "pid,ppid,stat,etime,args"],
                           capture_output=True, text=True)
    return table.stdout


def wait_for(condition, timeout: float, what: str, describe=lambda: "") -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"timed out after {timeout:.0f} s waiting for {what}\n{describe()}"
        time.sleep(0.2)


def graph_logs(output: str) -> str:
    match = re.search(r"logs in (\S*/ball_balance_graph\.\w+)", output)
    return "".join(p.read_text(errors="replace") for p in Path(match.group(1)).glob("*.log")) if match else ""


@pytest.mark.parametrize("script, args, line", [
    ("sim_balance.sh", ["--duration", "-3"], "sim_balance.sh: --duration takes a number >= 0, got '-3'"),
    ("sim_pid.sh", ["--radius", "0.1m"], "sim_balance.sh: --radius takes a number >= 0, got '0.1m'"),
    ("sim_policy_in_manager.sh", ["--duration", "abc"],
     "sim_policy_in_manager.sh: --duration takes a number >= 0, got 'abc'"),
])
def test_a_bad_value_is_refused_before_anything_starts(launcher, script, args, line):
    # a negative --duration never ended; other values started the graph and then stopped it
    result = launcher.run(["bash", str(ROOT / "scripts" / script), *args], timeout=60)
    assert result.returncode == 2 and result.stderr.strip() == line, result.stderr[-2000:]


@pytest.mark.parametrize("script, args, line", [
    ("sim_mpc.sh", ["--param", "mpc_horizon:=0"], "ball_balance_mpc: cannot start: parameter 'mpc_horizon'"),
    ("sim_pid.sh", ["--reference", "nonsense"], "ball_balance_controller: cannot start: parameter 'reference_kind'"),
    ("sim_balance.sh", ["--tracker-param", "source:=webcam"], "ball_tracker: cannot start: parameter 'source'"),
    # the controller inside the manager: loaded and configured by a manager of its own on the mock arm
    ("sim_policy_in_manager.sh", ["--reference", "nonsense"],
     "ros2_control_node: cannot start: controller 'ball_balance_controller': parameter 'reference_kind'"),
])
def test_a_bad_node_parameter_is_refused_before_anything_starts(launcher, script, args, line):
    # found by the node itself, built but not started, before the graph starts
    result = launcher.run(["bash", str(ROOT / "scripts" / script), *args], timeout=120)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and lines[0].startswith(line), result.stderr[-2000:]


@pytest.mark.parametrize("script", ["sim_arm.sh", "sim_pid.sh", "tracker_usb.sh"])
def test_a_domain_dds_cannot_use_is_refused_with_one_line(launcher, script):
    # DDS derives its ports from the domain: past 232 every process printed a transport error
    env = {**ros_env(launcher.domain_id), "ROS_DOMAIN_ID": "233"}
    result = launcher.run(["bash", str(ROOT / "scripts" / script)], timeout=60, env=env)
    assert result.returncode == 2, result.stderr[-2000:]
    assert result.stderr.strip().splitlines() == [
        f"{script.replace('sim_pid', 'sim_balance')}: ROS_DOMAIN_ID=233 is not a ROS domain: take 0-232 "
        "(0-101 keep clear of Linux's ephemeral ports)"], result.stderr


def test_sim_balance_with_a_duration_ends_when_the_controller_manager_dies(launcher):
    graph = start_graph(launcher, "--duration", "300")
    wait_for(lambda: "[monitor] t" in graph.output(), 120, "the monitor's first progress line")
    (manager,) = session_pids(graph, "ros2_control_node --ros-args")
    os.kill(manager, signal.SIGKILL)
    assert graph.wait(timeout=60) == 3, graph.output()
    assert "sim_balance.sh: sim exited; stopping the graph" in graph.output()
    # a killed manager's camera renderer (with the camera on) is orphaned before the script can
    # note it, and ends on its own once its pipe closes: on a loaded machine that can outlast the
    # script by a moment, so the end of the session's processes is awaited with a deadline
    wait_for(lambda: session_pids(graph, "ball_balance") == [], 20, "the graph's processes to end",
             lambda: session_table(graph))


def test_a_second_ctrl_c_stops_the_graph_without_a_traceback(launcher):
    graph = start_graph(launcher)
    wait_for(lambda: "[monitor] t" in graph.output(), 120, "the monitor's first progress line")
    os.killpg(graph.popen.pid, signal.SIGINT)  # what a terminal's Ctrl-C does: the whole group
    time.sleep(0.5)  # the second Ctrl-C lands while the nodes shut down
    os.killpg(graph.popen.pid, signal.SIGINT)
    graph.wait(timeout=60)
    # as above: a renderer orphaned by the stop ends on its own once its pipe closes
    wait_for(lambda: session_pids(graph, "ball_balance") == [], 20, "the graph's processes to end",
             lambda: session_table(graph))
    logs = graph.output() + graph_logs(graph.output())
    assert "Traceback" not in logs, logs[-3000:]


def test_stop_all_also_ends_what_a_started_process_started(tmp_path):
    # a helper shell function in the background dies on SIGTERM in the middle of a command:
    # that command (here a sleeper, in the graph a `ros2py service call`) must not outlive the script
    script = tmp_path / "graph.sh"
    script.write_text(f"""set -euo pipefail
source "{ROOT}/scripts/lib/stop_all.sh"
trap stop_all INT TERM EXIT
helper() {{ python -c "import time; time.sleep(300)" helper-child-of-{tmp_path.name}; }}
helper &
PIDS+=($!)
sleep 300 &
PIDS+=($!)
for _ in $(seq 100); do pgrep -f helper-child-of-{tmp_path.name} >/dev/null && break; sleep 0.1; done
exit 3
""")
    started = time.monotonic()
    graph = subprocess.Popen(["bash", str(script)], start_new_session=True)
    assert graph.wait(timeout=60) == 3
    assert time.monotonic() - started < 20   # each process ended on SIGTERM; none waited out its 6 s
    survivors = subprocess.run(["pgrep", "-s", str(graph.pid), "-f", f"helper-child-of-{tmp_path.name}"],
                               capture_output=True, text=True).stdout.split()
    assert survivors == []
