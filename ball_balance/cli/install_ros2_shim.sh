#!/usr/bin/env bash
# install_ros2_shim.sh VENV: put our `ros2` shim into VENV/bin unless a real ROS 2 `ros2` exists.
# Called by scripts/setup.sh. A shim left over from an earlier run is removed once a real
# `ros2` appears (e.g. ROS 2 was installed since).
set -euo pipefail
venv="$1"
shim_src="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)/ros2_shim.sh"
target="$venv/bin/ros2"
real=""
IFS=: read -ra path_dirs <<<"${PATH:-}"
for dir in "${path_dirs[@]}"; do
  candidate="${dir:-.}/ros2"
  [[ -x "$candidate" && ! -d "$candidate" ]] || continue
  grep -q "ros2py-shim-marker" "$candidate" 2>/dev/null && continue
  real="$candidate"; break
done
if [[ -n "$real" ]]; then
  if [[ -f "$target" ]] && grep -q "ros2py-shim-marker" "$target"; then rm -f "$target"; fi
  echo "a real ros2 exists ($real): no ros2 shim installed"
elif [[ ! -e "$target" ]] || grep -q "ros2py-shim-marker" "$target"; then
  install -m 755 "$shim_src" "$target"
fi
