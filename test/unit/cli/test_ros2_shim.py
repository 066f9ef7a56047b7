"""The `ros2` shim: runs a real ROS 2 `ros2` when one exists, ros2py otherwise; installed only
where no real one exists."""
import os
import subprocess
from pathlib import Path

CLI = Path(__file__).resolve().parents[3] / "ball_balance" / "cli"


def fake_command(folder: Path, name: str, says: str) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(f'#!/bin/sh\necho "{says} $*"\n')
    path.chmod(0o755)


def run(cmd, path_dirs):
    env = dict(os.environ, PATH=os.pathsep.join([*map(str, path_dirs), "/usr/bin", "/bin"]))
    return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=30)


def install_shim(venv: Path, path_dirs):
    (venv / "bin").mkdir(parents=True, exist_ok=True)
    return run([str(CLI / "install_ros2_shim.sh"), str(venv)], [venv / "bin", *path_dirs])


def test_shim_runs_ros2py_when_no_real_ros2_exists(tmp_path):
    venv, tools = tmp_path / "venv", tmp_path / "tools"
    fake_command(tools, "ros2py", "ros2py")
    install_shim(venv, [tools])
    result = run([str(venv / "bin" / "ros2"), "topic", "list"], [venv / "bin", tools])
    assert result.stdout == "ros2py topic list\n"


def test_shim_defers_to_a_real_ros2_later_on_path(tmp_path):
    venv, tools, ros = tmp_path / "venv", tmp_path / "tools", tmp_path / "opt_ros"
    fake_command(tools, "ros2py", "ros2py")
    install_shim(venv, [tools])
    fake_command(ros, "ros2", "real ros2")  # ROS 2 sourced after set-up: later on PATH
    result = run([str(venv / "bin" / "ros2"), "topic", "list"], [venv / "bin", tools, ros])
    assert result.stdout == "real ros2 topic list\n"


def test_no_shim_is_installed_where_a_real_ros2_exists(tmp_path):
    venv, ros = tmp_path / "venv", tmp_path / "opt_ros"
    fake_command(ros, "ros2", "real ros2")
    result = install_shim(venv, [ros])
    assert not (venv / "bin" / "ros2").exists()
    assert "a real ros2 exists" in result.stdout
