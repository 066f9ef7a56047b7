#!/usr/bin/env bash
# Set-up time from nothing (fresh clone, empty pip cache) and when up to date.
# usage: benchmarks/setup_bench.sh     (clones the current HEAD into a temporary folder)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
WORK="$(mktemp -d)"; trap 'rm -rf "$WORK"' EXIT
git clone -q "$ROOT" "$WORK/clone"
seconds() { local t0=$EPOCHREALTIME; "$@" >"$WORK/out.log" 2>&1; awk -v a="$t0" -v b="$EPOCHREALTIME" "BEGIN { print b - a }"; }
fresh=$(PIP_NO_CACHE_DIR=1 seconds "$WORK/clone/scripts/setup.sh")
again=$(seconds "$WORK/clone/scripts/setup.sh")
touch "$WORK/clone/ball_tracker_msgs/msg/BallState.msg"; echo "# touched" >>"$WORK/clone/ball_tracker_msgs/msg/BallState.msg"
rebuild=$(seconds "$WORK/clone/scripts/setup.sh")
printf '%-48s %8s\n' "set-up step" "seconds"
printf '%-48s %8.1f\n' "from nothing (fresh clone, no pip cache)" "$fresh"
printf '%-48s %8.2f\n' "up to date (nothing changed)" "$again"
printf '%-48s %8.1f\n' "after editing BallState.msg (incremental colcon)" "$rebuild"
