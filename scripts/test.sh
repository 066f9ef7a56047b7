#!/usr/bin/env bash
# Set up the workspace (fast when up to date) and run the whole test suite:
# lint, controller_manager_py's tests on their own, unit tests, then integration tests over DDS.
# Extra arguments go to pytest (which then runs controller_manager_py's tests in the suite).
#
#   scripts/test.sh                                               the whole suite
#   scripts/test.sh -q test/integration/test_graph_scripts.py -k refused   lint, then those tests
#   scripts/test.sh --help                                        this text (and nothing else)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
usage() { sed -n '2,/^[^#]/{/^#/p}' "$0" | sed 's/^# \{0,1\}//'; }   # the header comment
for arg; do
  case "$arg" in -h|--help) usage; exit 0 ;; esac
done
"$ROOT/scripts/setup.sh"
# the live view's browser test drives Debian's Chromium (without it that test is skipped)
command -v chromium >/dev/null 2>&1 || "$ROOT/scripts/tools/install_test_browser.sh" \
  || echo "[test] chromium could not be installed: the live view's browser tests are skipped" >&2
source "$ROOT/env.sh"
cd "$ROOT"
echo "[test] ruff check"
ruff check --quiet ball_balance controller_manager_py test scripts
if (($# == 0)); then
  # controller_manager_py's own tests, without ball_balance on the path (it is a package of
  # its own); the pytest run below is then the rest (test/ only)
  echo "[test] controller_manager_py alone"
  controller_manager_py/test/run_standalone.sh -q
  # ... and installed with pip into a fresh venv, as a user of the package has it
  echo "[test] controller_manager_py installed"
  controller_manager_py/test/run_installed.sh -q
  echo "[test] pytest"
  exec python -m pytest --durations=15 test
fi
echo "[test] pytest"
exec python -m pytest "$@"
