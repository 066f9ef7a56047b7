#!/usr/bin/env bash
# Set up the workspace (fast when up to date) and run the whole test suite:
# lint, unit tests, then integration tests over DDS. Extra arguments go to pytest.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$ROOT/scripts/setup.sh"
source "$ROOT/env.sh"
cd "$ROOT"
echo "[test] ruff check"
ruff check --quiet ball_balance controller_manager_py test scripts
echo "[test] pytest"
exec python -m pytest "$@"
