#!/usr/bin/env bash
# ball_balance `ros2` shim (installed into the venv by scripts/setup.sh only when no real
# ROS 2 `ros2` command was found). It never shadows a real one: if a `ros2` other than
# this file is on PATH (e.g. /opt/ros/jazzy/bin after sourcing ROS later), it runs that;
# otherwise it runs our `ros2py`, which has the same verbs.
# ros2py-shim-marker
self="$(readlink -f "${BASH_SOURCE[0]}")"
IFS=: read -ra path_dirs <<<"${PATH:-}"
for dir in "${path_dirs[@]}"; do
  candidate="${dir:-.}/ros2"
  [[ -x "$candidate" && ! -d "$candidate" ]] || continue
  [[ "$(readlink -f "$candidate")" == "$self" ]] && continue
  grep -q "ros2py-shim-marker" "$candidate" 2>/dev/null && continue
  exec "$candidate" "$@"
done
if command -v ros2py >/dev/null 2>&1; then
  exec ros2py "$@"
fi
root="$(cd "$(dirname "$self")/../.." && pwd)"
[[ -f "$root/env.sh" ]] || { echo "ros2: no ROS 2 and no ros2py found; run scripts/setup.sh" >&2; exit 1; }
# shellcheck disable=SC1091
source "$root/env.sh" && exec ros2py "$@"
