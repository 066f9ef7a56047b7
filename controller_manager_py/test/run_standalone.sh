#!/usr/bin/env bash
# controller_manager_py's tests on their own: pytest from the package folder with only that
# folder, its entry points and the ROS/Python packages on the path, never the repository
# around it. Fails when `ball_balance` (or any application) is importable in that run, or when
# `controller_manager_py` comes from anywhere but this folder.
#
#   controller_manager_py/test/run_standalone.sh [pytest args]
#
# Needs a ROS 2 Jazzy environment with the interface packages (control_msgs,
# controller_manager_msgs, pal_statistics_msgs): here `source env.sh`, which it does itself
# when nothing is sourced. PYTHON chooses the interpreter (default: the repository's .venv, else python3).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/standalone_env.sh"

# the entry points (plugins) as an installed package has them, from our setup.py alone
(cd "$PKG" && "$PYTHON" setup.py -q egg_info --egg-base "$TMP" >"$TMP/egg_info.log" 2>&1) \
  || { cat "$TMP/egg_info.log" >&2; echo "run_standalone: setup.py egg_info failed" >&2; exit 1; }

# PYTHONPATH: this folder, the egg-info, and the environment's entries
path="$PKG:$TMP${ENV_PYTHONPATH:+:$ENV_PYTHONPATH}"

cd "$PKG"
PYTHONPATH="$path" "$PYTHON" -P - "$PKG" <<'PY'
import importlib.util, sys
from pathlib import Path
from importlib.metadata import entry_points

pkg = Path(sys.argv[1])
assert importlib.util.find_spec("ball_balance") is None, "ball_balance is importable: not a standalone run"
import controller_manager_py
where = Path(controller_manager_py.__file__).resolve()
assert where.is_relative_to(pkg), f"controller_manager_py from {where}, not from {pkg}"
hardware = sorted(ep.name for ep in entry_points(group="controller_manager_py.hardware"))
assert hardware == ["mock_components/GenericSystem"], hardware
print(f"run_standalone: controller_manager_py from {where.parent}; ball_balance not importable")
PY
PYTHONPATH="$path" exec "$PYTHON" -P -m pytest -p no:cacheprovider "$@"
