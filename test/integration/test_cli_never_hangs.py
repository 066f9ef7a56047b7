"""A ros2py command that has done its work ends with its own exit code even when rclpy's
teardown never returns, and the graph scripts' start-up gives up in bounded time, naming what
did not come up, even when a ros2py call hangs."""
import os
import re
import subprocess
import textwrap
import time
from pathlib import Path

import pytest

from ball_balance.cli.main import TEARDOWN_DEADLINE_S
from harness import ROOT, python_cmd

pytestmark = pytest.mark.integration

# ros2py's main with rclpy's Node.destroy_node hanging for ever (with rclpy 7.1.6 one `topic
# info` spent over ten minutes there). It first says on stderr when the hang began, by
# time.monotonic(), a clock every process shares.
HANGING_TEARDOWN = textwrap.dedent("""
    import ctypes, sys, time
    import rclpy.node
    from ball_balance.cli.main import main

    def destroy_node_hangs(node):
        print(f"destroy_node hangs from {time.monotonic()}", file=sys.stderr, flush=True)
        while True:
            if sys.argv[1] == "holding-the-lock":
                ctypes.PyDLL(None).sleep(3600)  # in C with the interpreter lock held, as rclpy's bindings are
            else:
                time.sleep(3600)

    rclpy.node.Node.destroy_node = destroy_node_hangs
    sys.exit(main(sys.argv[2:]))
""")
HANG_MARK = "destroy_node hangs from "
# What a loaded machine may add to the deadline (start of the timer's thread, the process's
# end); a hang that is not cut short runs into the run's timeout instead.
SLACK_S = 20.0


def ros2py_with_hanging_teardown(launcher, hang: str, *argv: str):
    """Run ros2py ARGV with the hang; (its result, seconds from the hang's start to its end)."""
    result = launcher.run(python_cmd("-c", HANGING_TEARDOWN, hang, *argv), timeout=120)
    ended = time.monotonic()
    began = re.search(rf"{HANG_MARK}([0-9.]+)", result.stderr)
    assert began, f"the teardown never reached destroy_node:\n{result.stderr}"
    return result, ended - float(began.group(1))


def other_lines(text: str):
    return [line for line in text.splitlines() if not line.startswith(HANG_MARK)]


@pytest.mark.parametrize("hang", ["holding-the-lock", "in-python"])
def test_topic_info_prints_and_exits_0_when_rclpy_teardown_hangs(launcher, graph, hang):
    from std_msgs.msg import String

    graph.node.create_publisher(String, "/x", 10)
    result, hung_s = ros2py_with_hanging_teardown(launcher, hang, "topic", "info", "/x", "--spin-time", "30")
    assert result.returncode == 0, result.stderr
    assert result.stdout == "Type: std_msgs/msg/String\nPublisher count: 1\nSubscription count: 0\n"
    assert other_lines(result.stderr) == []
    assert hung_s < TEARDOWN_DEADLINE_S + SLACK_S


def test_a_failing_command_keeps_its_one_line_and_exit_1_when_rclpy_teardown_hangs(launcher):
    result, hung_s = ros2py_with_hanging_teardown(launcher, "holding-the-lock", "topic", "info", "/nothing",
                                                  "--spin-time", "2")
    assert result.returncode == 1
    assert result.stdout == ""
    (line,) = other_lines(result.stderr)
    assert line.startswith("ros2py: topic '/nothing' not found")
    assert hung_s < TEARDOWN_DEADLINE_S + SLACK_S


# A stand-in for ros2py: the calls listed in HANG_CALLS (1-based; "all": every one) hang,
# ignoring SIGTERM as a process stuck in C does; the others answer as `topic info` does.
FAKE_ROS2PY = """#!/bin/bash
echo $$ >>"$FAKE_ROS2PY_CALLS"
call=$(wc -l <"$FAKE_ROS2PY_CALLS")
if [[ "$HANG_CALLS" == all || " $HANG_CALLS " == *" $call "* ]]; then trap '' TERM; exec sleep 600; fi
printf 'Type: std_msgs/msg/String\\nPublisher count: 1\\nSubscription count: 1\\n'
"""


def wait_for_endpoint(tmp_path, hang_calls: str, *args: str, call_timeout_s: int = 3):
    """`wait_for_endpoint ARGS` of scripts/lib/graph.sh against FAKE_ROS2PY: (result, seconds, pids of the calls)."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "ros2py").write_text(FAKE_ROS2PY)
    (bin_dir / "ros2py").chmod(0o755)
    calls = tmp_path / "calls"
    env = dict(os.environ, PATH=f"{bin_dir}{os.pathsep}{os.environ['PATH']}", FAKE_ROS2PY_CALLS=str(calls),
               HANG_CALLS=hang_calls, ROS2PY_TIMEOUT_S=str(call_timeout_s))
    script = f'source "{ROOT}/scripts/lib/graph.sh"; wait_for_endpoint "$@"'
    started = time.monotonic()
    result = subprocess.run(["bash", "-c", script, "sim_balance.sh", *args], env=env, capture_output=True,
                            text=True, timeout=120, start_new_session=True)
    return result, time.monotonic() - started, [int(pid) for pid in calls.read_text().split()]


def gone(pid: int) -> bool:
    """Ended: no such process, or a zombie (`timeout -k` kills its own group, itself too, so
    the killed call is left to init to reap)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return True
    return stat.rsplit(")", 1)[1].split()[0] == "Z"


def test_graph_start_up_goes_on_past_a_ros2py_call_that_hangs(tmp_path):
    result, took_s, pids = wait_for_endpoint(tmp_path, "1", "/ball_state", "Publisher", "120")
    assert result.returncode == 0, result.stderr
    assert len(pids) == 2
    assert all(gone(pid) for pid in pids)   # the hung call was killed (SIGKILL: it ignored SIGTERM)
    assert took_s < 100                     # the second call, not the 120 s deadline, ended it


def test_graph_start_up_names_the_topic_and_endpoint_that_did_not_come_up_when_ros2py_hangs(tmp_path):
    result, took_s, pids = wait_for_endpoint(tmp_path, "all", "/ball_reference", "Subscription", "8")
    assert result.returncode == 1
    assert result.stderr == ("sim_balance.sh: no subscription on /ball_reference after 8 s (the last "
                             "`ros2py topic info /ball_reference` did not answer in time)\n")
    assert all(gone(pid) for pid in pids)
    assert took_s < 8 + 5 + SLACK_S         # the deadline, SIGKILL 5 s after the last call's SIGTERM
