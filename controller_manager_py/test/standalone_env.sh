# Sourced by run_standalone.sh and run_installed.sh: the package and repository folders, a
# ROS environment (env.sh when nothing is sourced), the interpreter (PYTHON, default the
# repository's .venv), a temporary folder removed at exit, and ENV_PYTHONPATH: the
# environment's PYTHONPATH entries that hold no application package and no copy of this one
# (the repository itself and colcon's build folders go).
PKG="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"   # the package folder (package.xml, setup.py)
REPO="$(cd "$PKG/.." && pwd)"
if [[ -z "${AMENT_PREFIX_PATH:-}" && -f "$REPO/env.sh" ]]; then
  source "$REPO/env.sh"
fi
PYTHON="${PYTHON:-}"
if [[ -z "$PYTHON" ]]; then
  if [[ -x "$REPO/.venv/bin/python" ]]; then PYTHON="$REPO/.venv/bin/python"; else PYTHON=python3; fi
fi
TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT
ENV_PYTHONPATH=""
IFS=: read -ra _entries <<<"${PYTHONPATH:-}"
for _entry in "${_entries[@]}"; do
  [[ -z "$_entry" || "$_entry" == "$REPO" || "$_entry" == "$REPO/build"* ]] && continue
  [[ -e "$_entry/ball_balance" || -e "$_entry/controller_manager_py" ]] && continue
  ENV_PYTHONPATH="${ENV_PYTHONPATH:+$ENV_PYTHONPATH:}$_entry"
done
