"""The ROS-installation path of scripts/setup.sh, on a stand-in Jazzy installation.

scripts/tools/standin_jazzy.sh installs the pinned Jazzy packages into a prefix with a
setup.bash, for the system Python, as /opt/ros/jazzy would hold them. A copy of this
repository then runs scripts/setup.sh with that setup.bash sourced (system mode: a venv with
system site packages, numpy 1.26 and OpenCV 4.10, only the interface packages the
installation lacks built), and nodes are started as `ros2 run` starts them. docs/setup.md,
"How system mode is tested", says what this does and does not prove.

Slow the first time (about 10 min at load 17 on 2 cores, colcon 8 min of it), so both the
stand-in and the workspace's venv, build and install folders are kept between runs, each
rebuilt from scratch when what decides it changes (the stand-in: the pins and its script;
the workspace: setup.sh, the requirements and the stand-in). Every run copies the tracked
files afresh and runs setup.sh, which brings the kept workspace up to date (its own stamps:
colcon again when a package or interface changed); then about a minute.
"""
import fcntl
import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

from harness import ROOT, ros_env

pytestmark = [pytest.mark.integration, pytest.mark.slow]

STANDIN = Path(tempfile.gettempdir()) / f"ball_balance_standin_jazzy_{os.getuid()}"
WORKSPACE = Path(tempfile.gettempdir()) / f"ball_balance_system_mode_ws_{os.getuid()}"
KEPT = (".venv", "build", "install")  # what setup.sh made; the rest is the repository's files
# a kept workspace is thrown away when one of these (or the stand-in) changes
WORKSPACE_INPUTS = ("scripts/setup.sh", "requirements/python.txt", "requirements/ros-system.txt",
                    "scripts/tools/standin_jazzy.sh", "requirements/ros-jazzy-wheels.txt")


def clean_env(**extra) -> dict:
    """A login-like environment: nothing of our wheels venv or of a sourced workspace."""
    keep = {k: v for k, v in os.environ.items() if k in ("HOME", "USER", "LANG", "TMPDIR", "ROS_DOMAIN_ID",
                                                           "ROS_AUTOMATIC_DISCOVERY_RANGE")}
    keep["PATH"] = "/usr/local/bin:/usr/bin:/bin"
    keep.update(extra)
    return keep


def bash(script: str, cwd: Path, env: dict, timeout: float) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", "-c", script], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL)


def workspace_key() -> str:
    digest = hashlib.sha256()
    for name in WORKSPACE_INPUTS:
        digest.update((ROOT / name).read_bytes())
    digest.update((STANDIN / ".standin_stamp").read_bytes())
    return digest.hexdigest()[:16]


def copy_of_the_repository(dest: Path) -> Path:
    """The files git tracks, as they are in the working tree (what a clone of it would hold),
    in `dest`; setup.sh's folders there are kept while workspace_key() is unchanged."""
    key_file = dest / ".system_mode_key"
    key = workspace_key()
    if dest.exists() and not (key_file.exists() and key_file.read_text() == key):
        shutil.rmtree(dest)
    dest.mkdir(parents=True, exist_ok=True)
    for entry in dest.iterdir():  # files deleted from the repository must not linger
        if entry.name not in KEPT and entry != key_file:
            shutil.rmtree(entry) if entry.is_dir() and not entry.is_symlink() else entry.unlink()
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    files = [f for f in listed.decode().split("\0") if f and (ROOT / f).is_file()]
    subprocess.run(["cp", "--parents", "-t", str(dest), *files], cwd=ROOT, check=True)
    key_file.write_text(key)
    return dest


@pytest.fixture
def kept_workspace():
    """The kept workspace folder, held exclusively (parallel runs on this machine wait)."""
    with open(f"{WORKSPACE}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield WORKSPACE


@pytest.mark.timeout(1800)  # a fresh stand-in and workspace build: minutes on 2 busy cores
def test_setup_takes_the_system_mode_on_a_jazzy_installation_and_nodes_run_the_ros2_way(ros_domain,
                                                                                        kept_workspace):
    built = subprocess.run([str(ROOT / "scripts" / "tools" / "standin_jazzy.sh"), str(STANDIN)],
                           capture_output=True, text=True, timeout=900, env=clean_env())
    assert built.returncode == 0, built.stderr[-3000:]
    ws = copy_of_the_repository(kept_workspace)
    source = f"source {STANDIN}/setup.bash"
    setup = bash(f"{source} && scripts/setup.sh", ws, clean_env(), timeout=1500)
    assert setup.returncode == 0, (setup.stdout + setup.stderr)[-3000:]
    assert "ready (system mode)" in setup.stdout
    assert "using the installed" not in setup.stdout  # the stand-in has no tf2_msgs etc.: built here

    env = clean_env(**{k: v for k, v in ros_env(ros_domain).items() if k.startswith("ROS_")})
    shell = f"{source} && source env.sh && "
    where = bash(shell + "python -c 'import rclpy, numpy, cv2; print(rclpy.__file__, numpy.__version__, "
                 "cv2.__version__)'", ws, env, timeout=120)
    assert where.returncode == 0, where.stderr[-2000:]
    rclpy_file, numpy_version, cv2_version = where.stdout.split()
    assert rclpy_file.startswith(str(STANDIN)), "rclpy must come from the installation, not the venv"
    assert numpy_version.startswith("1.26") and cv2_version.startswith("4.10")

    manager = subprocess.Popen(
        ["bash", "-c", shell + "exec ros2 run ball_balance ros2_control_node --ros-args --params-file "
         "config/ur_controllers.yaml -p robot_description_file:=config/mock_ur.urdf"],
        cwd=ws, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        # polled until a deadline: each call takes seconds on a busy machine
        listing = bash(shell + "end=$((SECONDS + 150)); until out=$(ros2 control list_controllers 2>&1) && "
                       "[[ $(grep -c active <<<\"$out\") -ge 3 ]] || ((SECONDS >= end)); do sleep 0.5; done; "
                       "echo \"$out\"", ws, env, timeout=180)
        assert "joint_state_broadcaster" in listing.stdout and "forward_position_controller" in listing.stdout, \
            listing.stdout + listing.stderr
        echo = bash(shell + "ros2 topic echo /joint_states --once --timeout 30 --field name", ws, env, timeout=120)
        assert "shoulder_pan_joint" in echo.stdout, echo.stdout + echo.stderr
    finally:
        os.killpg(manager.pid, 2)
        try:
            manager.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(manager.pid, 9)
            manager.wait(timeout=5)
    output = manager.stdout.read()
    assert "Traceback" not in output, output[-3000:]
