"""ros2py's entry point: every failure is one line and a non-zero exit, never a traceback."""
import argparse
import subprocess
import sys
import types

import pytest

from ball_balance.cli import main as cli_main


def fake_verb_module(monkeypatch, handler):
    module = types.ModuleType("ball_balance.cli.fake")
    module.cmd = handler
    monkeypatch.setitem(sys.modules, "ball_balance.cli.fake", module)
    parser = cli_main.build_parser()
    original_parse = parser.parse_args

    def parse_args(argv):
        args = original_parse(["node", "list"])
        args._target = "fake:cmd"
        return args

    monkeypatch.setattr(parser, "parse_args", parse_args)
    monkeypatch.setattr(cli_main, "build_parser", lambda: parser)


def test_cli_error_is_one_line_exit_1(monkeypatch, capsys):
    from ball_balance.cli.errors import CliError

    def handler(args):
        raise CliError("topic '/x' not found")

    fake_verb_module(monkeypatch, handler)
    assert cli_main.main([]) == 1
    assert capsys.readouterr().err == "ros2py: topic '/x' not found\n"


def test_unexpected_exception_is_one_line_too(monkeypatch, capsys):
    def handler(args):
        raise RuntimeError("rcl said no\nsecond line")

    fake_verb_module(monkeypatch, handler)
    monkeypatch.delenv("ROS2PY_DEBUG", raising=False)
    assert cli_main.main([]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("ros2py: RuntimeError: rcl said no")


def test_ctrl_c_exits_quietly(monkeypatch, capsys):
    def handler(args):
        raise KeyboardInterrupt

    fake_verb_module(monkeypatch, handler)
    assert cli_main.main([]) == 0
    assert capsys.readouterr().err == ""


def test_help_needs_no_ros_import():
    code = ("import sys\nfrom ball_balance.cli.main import build_parser\nbuild_parser()\n"
            "sys.exit('rclpy' in sys.modules or 'yaml' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], timeout=60).returncode == 0


@pytest.mark.parametrize("argv, problem", [
    (["service", "call", "/x", "std_srvs/srv/Trigger", "--timeout", "-5"],
     "argument --timeout: expected a number > 0, got '-5'"),
    (["topic", "echo", "/x", "--timeout", "-1"], "argument --timeout: expected a number > 0, got '-1'"),
    (["tf", "echo", "a", "b", "--count", "-1"], "argument --count: expected an integer > 0, got '-1'"),
    (["bag", "record", "/x", "--duration", "-1"], "argument --duration: expected a number > 0, got '-1'"),
    (["bag", "play", "bag", "--start-offset", "-2"], "argument --start-offset: expected a number >= 0, got '-2'"),
    (["bag", "play", "bag", "--rate", "nan"], "argument -r/--rate: expected a number > 0, got 'nan'"),
    (["topic", "hz", "/x", "--window", "0"], "argument --window/-w: expected an integer > 0, got '0'"),
    (["topic", "echo"], "the following arguments are required: topic_name"),
])
def test_a_bad_argument_is_one_line_and_exit_2(capsys, argv, problem):
    with pytest.raises(SystemExit) as exited:
        cli_main.main(argv)
    assert exited.value.code == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"ros2py: {problem} (see `ros2py ") and line.endswith(" -h`)"), line


def test_every_numeric_option_refuses_what_makes_no_sense():
    """No option takes a bare float or int: a negative timeout or count is refused up front."""
    shared = {cli_main.positive_float, cli_main.non_negative_float, cli_main.positive_int, cli_main.non_negative_int}
    pending, typed = [cli_main.build_parser()], []
    while pending:
        parser = pending.pop()
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                pending.extend(action.choices.values())
            elif action.type is not None:
                typed.append((parser.prog, action.dest, action.type))
    assert typed and all(kind in shared for _, _, kind in typed), [t for t in typed if t[2] not in shared]


@pytest.mark.parametrize("argv, kind", [
    (["topic", "pub", "bad name", "std_msgs/msg/String"], "topic"),
    (["topic", "echo", "bad name", "std_msgs/msg/String"], "topic"),
    (["topic", "info", "bad name"], "topic"),
    (["service", "call", "bad name", "std_srvs/srv/Trigger"], "service"),
    (["action", "send_goal", "bad name", "control_msgs/action/FollowJointTrajectory", "{}"], "action"),
    (["bag", "record", "bad name", "-o", "never_made"], "topic"),
])
def test_an_invalid_name_is_one_line_and_exit_2_before_any_node(monkeypatch, capsys, tmp_path, argv, kind):
    from ball_balance.cli.session import Session

    def no_node(*args, **kwargs):
        raise AssertionError("a node was made for an invalid name")

    monkeypatch.setattr(Session, "__init__", no_node)
    monkeypatch.chdir(tmp_path)
    assert cli_main.main(argv) == 2
    assert capsys.readouterr().err == (
        f"ros2py: 'bad name' is not a valid {kind} name: it must not contain characters other than alphanumerics, "
        "'_', '~', '{', or '}' (character 4: ' ')\n")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name, problem", [
    ("/a//b", "it must not contain repeated '/' (character 4: '/')"),
    ("2d/pose", "a token must not start with a number (character 1: '2')"),
    ("ok/", "it must not end with a forward slash (character 3: '/')"),
    ("~/private", "'~' and '{...}' substitutions are not expanded by ros2py: give the full name"),
])
def test_names_are_checked_as_rcl_checks_them(name, problem):
    from ball_balance.cli.errors import BadArgument
    from ball_balance.cli.session import valid_name

    assert valid_name("ball_state") == "/ball_state" and valid_name("/ns/_hidden/x") == "/ns/_hidden/x"
    with pytest.raises(BadArgument) as raised:
        valid_name(name, "service")
    assert str(raised.value) == f"'{name}' is not a valid service name: {problem}"


def test_a_bag_folder_that_cannot_be_made_is_one_line_before_any_node(monkeypatch, capsys):
    from ball_balance.cli.session import Session

    monkeypatch.setattr(Session, "__init__", lambda *a, **k: pytest.fail("a node was made"))
    assert cli_main.main(["bag", "record", "-o", "/dev/null/x", "/x"]) == 1
    assert capsys.readouterr().err == "ros2py: cannot create the bag folder /dev/null/x: Not a directory\n"
