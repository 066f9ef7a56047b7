"""ros2py's entry point: every failure is one line and a non-zero exit, never a traceback."""
import subprocess
import sys
import types

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
