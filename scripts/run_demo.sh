#!/usr/bin/env bash
# THE main job: set up (scripts/setup.sh), start the simulated graph (MuJoCo UR arm in
# ros2_control_node, robot_state_publisher, ball_tracker on the simulated camera, the balance
# controller, the visualizer), release the ball off-centre, balance it at the centre, then
# track a circle (radius 0.10 m, period 10 s). Leaves in artifacts/demo/:
#   plot.png     ball path vs reference, error over time, tilt commands
#   camera.mp4   the overhead camera with the tracker's overlay, in real time (12 s from engaging)
#   metrics.txt  drop, RMSE (whole run and after 5 s), settling time, peak tilt, smoothness
# and prints the metrics. Ctrl-C stops everything.
#
#   scripts/run_demo.sh                      # MPC, 30 s of simulated time
#   scripts/run_demo.sh --controller pid     # the PID instead
#   scripts/run_demo.sh --duration 60 --out /tmp/demo
#   scripts/run_demo.sh --live-view-port 8081        # the live view elsewhere (--no-live-view: none)
# While it runs, the live view shows it in a browser: the script prints its address
# (http://127.0.0.1:8080/ by default; docs/live_view.md).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
CONTROLLER=mpc
DURATION=30
OUT="$ROOT/artifacts/demo"
LIVE_VIEW=(--live-view-port "${BALL_BALANCE_LIVE_VIEW_PORT:-8080}")
usage() { sed -n '2,/^[^#]/{/^#/p}' "$0" | sed 's/^# \{0,1\}//'; }   # the header comment
source "$ROOT/scripts/lib/args.sh"   # needs, require_*
while (($#)); do
  case "$1" in
    --controller) needs 1 "$@"; CONTROLLER="$2"; shift 2 ;;
    --duration) needs 1 "$@"; DURATION="$2"; shift 2 ;;
    --out) needs 1 "$@"; OUT="$2"; shift 2 ;;
    --live-view-port) needs 1 "$@"; LIVE_VIEW=(--live-view-port "$2"); shift 2 ;;
    --no-live-view) LIVE_VIEW=(--no-live-view); shift ;;
    -h|--help) usage; exit 0 ;;
    *) echo "run_demo.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
# bad values: one line before the set-up (sim_balance.sh checks the rest)
case "$CONTROLLER" in
  pid|mpc|policy) ;;
  *) echo "run_demo.sh: --controller must be pid, mpc or policy, got '$CONTROLLER'" >&2; exit 2 ;;
esac
require_number run_demo.sh --duration "$DURATION"
[[ "${LIVE_VIEW[0]}" == --no-live-view ]] || require_port run_demo.sh --live-view-port "${LIVE_VIEW[1]}"
require_out_dir run_demo.sh --out "$OUT"

echo "run_demo.sh: [1/3] set-up (scripts/setup.sh)" >&2
"$ROOT/scripts/setup.sh"
# shellcheck disable=SC1091
source "$ROOT/env.sh"
# keep the demo's DDS traffic on this machine unless told otherwise
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"

echo "run_demo.sh: [2/3] simulated graph: ball released at (0.08, -0.05) m, balanced at the centre for 6 s," \
     "then a circle r = 0.10 m, T = 10 s; ${DURATION} s of simulated time" >&2
STARTED="$(mktemp)"   # files in $OUT newer than this are this run's
set +e
"$ROOT/scripts/sim_balance.sh" --controller "$CONTROLLER" --ball 0.08 -0.05 \
  --reference circle --radius 0.10 --period 10 --start-delay 6 \
  --duration "$DURATION" --out "$OUT" --video-s 12 --debug-image "${LIVE_VIEW[@]}"
CODE=$?
set -e
if ((CODE == 2)); then   # refused before anything started (a bad value, the ROS domain taken)
  rm -f "$STARTED"
  echo "run_demo.sh: the graph was not started: the line above says why" >&2
  exit 2
fi

echo "run_demo.sh: [3/3] results in $OUT:" >&2
ls -l "$OUT" >&2 || true
WRITTEN="$(find "$OUT" -maxdepth 1 -type f -newer "$STARTED" -printf '%f ' 2>/dev/null)"
rm -f "$STARTED"
if [[ " $WRITTEN" == *" metrics.txt "* ]]; then   # not an earlier run's
  echo "--- metrics ($CONTROLLER) ---"
  cat "$OUT/metrics.txt"
fi
case "$CODE" in
  0) echo "run_demo.sh: done: the ball stayed on the plate" >&2 ;;
  1) echo "run_demo.sh: the ball DROPPED (see $OUT/plot.png)" >&2 ;;
  130) if [[ -n "$WRITTEN" ]]; then
         echo "run_demo.sh: interrupted: ${WRITTEN% } cover the run up to the interrupt" >&2
       else
         echo "run_demo.sh: interrupted before anything was written" >&2
       fi ;;
  *) echo "run_demo.sh: the graph did not produce results (exit $CODE); see the logs named above" >&2 ;;
esac
exit "$CODE"
