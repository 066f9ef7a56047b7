#!/usr/bin/env bash
# controller_manager_py installed as a user installs it, then its tests against that copy: a
# fresh venv on top of the environment's Python packages (rclpy, numpy, the message packages),
# `pip install` of this folder (a wheel built as pip builds it; no ball_balance anywhere),
# and pytest with the installed package, its entry points and its `ros2_control_node` (never
# this folder) on the path.
#
#   controller_manager_py/test/run_installed.sh [pytest args]
#
# Needs a ROS 2 Jazzy environment with the interface packages (control_msgs,
# controller_manager_msgs, pal_statistics_msgs): here `source env.sh`, which it does itself when
# nothing is sourced. PYTHON chooses the base interpreter (default: the repository's .venv).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/standalone_env.sh"

VENV="$TMP/venv"
"$PYTHON" -m venv --without-pip "$VENV"
# the base environment's packages (pip among them), as a site directory of the new venv (its
# .pth files count)
base_site="$("$PYTHON" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
venv_site="$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
echo "import site; site.addsitedir('$base_site')" > "$venv_site/base_environment.pth"
# the ROS wheels' shared libraries live in the base environment's prefix (their bootstrapper
# looks in the running interpreter's, the new venv's)
ros_libs="$("$PYTHON" -c 'import sys; print(sys.prefix)')/lib"
for libs in "$base_site"/ros_*.libs; do [[ -d "$libs" ]] && ros_libs="$ros_libs:$libs"; done
export LD_LIBRARY_PATH="$ros_libs${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
# PYTHONPATH: the environment's entries, not this folder
path="$ENV_PYTHONPATH"

cd "$TMP"
# built from a copy: a build writes its egg-info beside setup.py
mkdir "$TMP/src" && cp -r "$PKG/package.xml" "$PKG/setup.py" "$PKG/setup.cfg" "$PKG/README.md" "$PKG/resource" \
  "$PKG/controller_manager_py" "$TMP/src/"
PYTHONPATH="$path" "$VENV/bin/python" -m pip install --quiet --no-deps "$TMP/src" \
  >"$TMP/pip.log" 2>&1 || { cat "$TMP/pip.log" >&2; echo "run_installed: pip install failed" >&2; exit 1; }

PYTHONPATH="$path" "$VENV/bin/python" -P - "$VENV" <<'PY'
import importlib.util, sys
from pathlib import Path
from importlib.metadata import entry_points

venv = Path(sys.argv[1])
assert importlib.util.find_spec("ball_balance") is None, "ball_balance is importable: not a standalone install"
import controller_manager_py
where = Path(controller_manager_py.__file__).resolve()
assert where.is_relative_to(venv), f"controller_manager_py from {where}, not the installed copy in {venv}"
controllers = sorted(ep.name for ep in entry_points(group="controller_manager_py.controllers"))
assert "joint_trajectory_controller/JointTrajectoryController" in controllers, controllers
assert (venv / "bin" / "ros2_control_node").exists(), "no ros2_control_node console script"
print(f"run_installed: controller_manager_py installed in {where.parent}; ball_balance not importable")
PY
# the tests from this folder, the package from the venv (pythonpath: the tests' helpers only)
PYTHONPATH="$path" PATH="$VENV/bin:$PATH" exec "$VENV/bin/python" -P -m pytest -p no:cacheprovider \
  -c "$PKG/pytest.ini" --rootdir "$PKG" -o pythonpath=test "$PKG/test" "$@"
