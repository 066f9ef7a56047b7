"""A ros2py command that has done its work ends with its own exit code even when rclpy's
teardown never returns."""
import re
import textwrap
import time

import pytest

from ball_balance.cli.main import TEARDOWN_DEADLINE_S
from harness import python_cmd

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
