"""Parameters given by name mistakes: unknown keys in a file are reported, undeclared names named."""
import time

import pytest

from harness import executable

pytestmark = pytest.mark.integration

TYPO_FILE = "ball_balance_visualizer:\n  ros__parameters:\n    rate_hzz: 5.0\n"


def wait_for_output(process, text, timeout=30.0):
    deadline = time.monotonic() + timeout
    while text not in process.output():
        assert process.running or text in process.output(), process.output()
        assert time.monotonic() < deadline, f"no '{text}' within {timeout} s:\n{process.output()}"
        time.sleep(0.1)


def test_a_typo_in_a_parameter_file_is_warned_about_naming_the_key(launcher, tmp_path):
    params = tmp_path / "vis.yaml"
    params.write_text(TYPO_FILE)
    node = launcher.start([executable("ball_balance_visualizer"), "--ros-args", "--params-file", str(params)])
    wait_for_output(node, "unknown parameter(s) given to /ball_balance_visualizer: rate_hzz (did you mean rate_hz?)")
    assert node.running


def test_unknown_parameters_error_refuses_to_start_with_one_line(launcher, tmp_path):
    params = tmp_path / "vis.yaml"
    params.write_text(TYPO_FILE)
    result = launcher.run([executable("ball_balance_visualizer"), "--ros-args", "--params-file", str(params),
                           "-p", "unknown_parameters:=error"], timeout=60)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ball_balance_visualizer: cannot start: "), result.stderr
    assert "rate_hzz" in lines[0]


# every node that runs until stopped (camera_snapshot refuses to start without a file to write),
# with what it needs beside the tests that run at the same time
NODES = {"ball_tracker": [], "ball_balance_controller": [], "ball_balance_mpc": [], "ball_balance_policy": [],
         "robot_manager": [], "robot_state_publisher": [], "ros2_control_node": [],
         "ball_balance_live_view": ["-p", "port:=0"], "ball_balance_foxglove": ["-p", "port:=0"],
         "ball_balance_visualizer": []}


@pytest.mark.parametrize("name", NODES)
def test_a_refused_node_says_only_why_and_a_started_one_what_it_does(launcher, name):
    command = [executable(name), "--ros-args", *NODES[name]]
    refused = launcher.run([*command, "-p", "frobnicate:=1", "-p", "unknown_parameters:=error"], timeout=60)
    lines = refused.stdout.strip().splitlines() + refused.stderr.strip().splitlines()
    assert refused.returncode == 2 and len(lines) == 1, lines
    assert lines[0].startswith(f"{name}: cannot start: ") and "frobnicate" in lines[0]
    started = launcher.start(command)
    wait_for_output(started, "[INFO]", timeout=60)


def test_param_set_of_an_undeclared_name_names_it(launcher, graph):
    launcher.start([executable("ball_balance_visualizer")])
    graph.wait_for_service("/ball_balance_visualizer/set_parameters", timeout=30)
    result = launcher.run([executable("ros2py"), "param", "set", "/ball_balance_visualizer", "rate_hzz", "5.0"],
                          timeout=40)
    assert result.returncode == 1 and result.stdout == ""
    assert result.stderr.strip() == (
        "ros2py: Setting parameter failed: 'rate_hzz' is not declared by /ball_balance_visualizer "
        "(did you mean rate_hz? `ros2py param list /ball_balance_visualizer` shows its parameters)")


def test_service_call_asks_a_node_in_another_process_and_prints_as_ros2cli(launcher):
    launcher.start([executable("ball_balance_visualizer"), "--ros-args", "-p", "rate_hz:=12.5"])
    result = launcher.run([executable("ros2py"), "service", "call", "/ball_balance_visualizer/get_parameters",
                           "rcl_interfaces/srv/GetParameters", "{names: [rate_hz]}", "--timeout", "60"], timeout=90)
    assert result.returncode == 0, result.stderr
    assert "requester: making request: rcl_interfaces.srv.GetParameters_Request(names=['rate_hz'])\n" in result.stdout
    assert "response:\nrcl_interfaces.srv.GetParameters_Response(values=[rcl_interfaces.msg.ParameterValue(type=3, " \
        in result.stdout
    assert "double_value=12.5" in result.stdout


def test_service_call_refuses_bad_values_with_one_line_before_calling(launcher):
    result = launcher.run([executable("ros2py"), "service", "call", "/sim/set_pause", "std_srvs/srv/SetBool",
                           "{dat: true}"], timeout=30)
    assert result.returncode == 1 and result.stdout == ""
    assert result.stderr.strip() == "ros2py: std_srvs/srv/SetBool_Request has no field 'dat' (fields: data)"


def test_param_describe_shows_the_schema_description_and_range_as_ros2cli(launcher, graph):
    launcher.start([executable("ball_balance_visualizer")])
    graph.wait_for_service("/ball_balance_visualizer/describe_parameters", timeout=30)
    result = launcher.run([executable("ros2py"), "param", "describe", "/ball_balance_visualizer", "rate_hz"],
                          timeout=40)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("Parameter name: rate_hz\n  Type: double\n  Description: "), result.stdout
    assert "  Constraints:\n    Read only: true\n    Min value: 1.0\n    Max value: 100.0\n" in result.stdout
    typo = launcher.run([executable("ros2py"), "param", "describe", "/ball_balance_visualizer", "rate_hzz"],
                        timeout=40)
    assert typo.returncode == 1 and typo.stdout == ""
    assert "ros2py: parameter 'rate_hzz' is not declared by /ball_balance_visualizer (did you mean rate_hz?" \
        in typo.stderr
