#!/usr/bin/env bash
# The balance controller against a REAL UR arm behind Universal Robots' ROS 2 driver.
# THE ARM WILL MOVE: first to the home pose (plate level), then to balance the ball. The script
# refuses to start without --i-know-the-arm-will-move, and refuses when the arm is more than
# --max-home-distance rad (any joint) away from home (jog it close first, with the pendant).
#
# Before: start the driver yourself, with the external-control program running on the robot:
#   ros2 launch ur_robot_driver ur_control.launch.py ur_type:=ur5e robot_ip:=<ip> \
#       initial_joint_controller:=scaled_joint_trajectory_controller
# and have the overhead camera connected (the tracker runs here, scripts/tracker_usb.sh options).
#
#   scripts/real_ur.sh --controller pid --i-know-the-arm-will-move
#   scripts/real_ur.sh --controller mpc --device /dev/video2 --calibration config/usb_camera.yaml \
#       --i-know-the-arm-will-move
#   scripts/real_ur.sh --dry-run            # print the steps, move nothing
#
# Controller switches (through `ros2 control`, or `ros2py control` when ROS 2 is absent):
#   pid: activate forward_position_controller, deactivate scaled_joint_trajectory_controller
#   mpc: activate scaled_joint_trajectory_controller, deactivate forward_position_controller
# On exit (Ctrl-C) the nodes stop; the arm holds its last commanded pose (the driver keeps it).
# Topics: /joint_states (driver) -> controller; /camera -> ball_tracker -> /ball_state ->
# controller -> /forward_position_controller/commands (pid) or
# /scaled_joint_trajectory_controller/joint_trajectory (mpc); /plate_cmd -> tracker.
# Parameters: config/pid.yaml or config/mpc.yaml; override with --param name:=value. The home
# pose is home_positions_rad (robot.HOME_POSITIONS_RAD); real arms usually need their own.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [[ -z "${BALL_BALANCE_ROOT:-}" ]]; then
  # shellcheck disable=SC1091
  source "$ROOT/env.sh"
fi

CONTROLLER=pid
CONFIRMED=0
DRY_RUN=0
MAX_HOME_DISTANCE=0.3
TRACKER_ARGS=()
CTRL_PARAMS=()
usage() { sed -n '2,/^[^#]/{/^#/p}' "$0" | sed 's/^# \{0,1\}//'; }   # the header comment
source "$ROOT/scripts/lib/args.sh"   # needs, require_*
while (($#)); do
  case "$1" in
    --controller) needs 1 "$@"; CONTROLLER="$2"; shift 2 ;;
    --i-know-the-arm-will-move) CONFIRMED=1; shift ;;
    --dry-run) DRY_RUN=1; shift ;;
    --max-home-distance) needs 1 "$@"; MAX_HOME_DISTANCE="$2"; shift 2 ;;
    --device|--calibration) needs 1 "$@"; TRACKER_ARGS+=("$1" "$2"); shift 2 ;;
    # checked here too: scripts/tracker_usb.sh starts after the controllers are switched
    --size) needs 1 "$@"; require_size real_ur.sh "$1" "$2"; TRACKER_ARGS+=("$1" "$2"); shift 2 ;;
    --fps) needs 1 "$@"; require_number real_ur.sh "$1" "$2"; TRACKER_ARGS+=("$1" "$2"); shift 2 ;;
    --param) needs 1 "$@"; CTRL_PARAMS+=(-p "$2"); shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "real_ur.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
case "$CONTROLLER" in
  pid) EXE=ball_balance_controller; YAML="$ROOT/config/pid.yaml"
       ACTIVATE=forward_position_controller; DEACTIVATE=scaled_joint_trajectory_controller ;;
  mpc) EXE=ball_balance_mpc; YAML="$ROOT/config/mpc.yaml"
       ACTIVATE=scaled_joint_trajectory_controller; DEACTIVATE=forward_position_controller ;;
  *) echo "real_ur.sh: --controller must be pid or mpc, got '$CONTROLLER'" >&2; exit 2 ;;
esac
if command -v ros2 >/dev/null 2>&1; then CTL=(ros2 control); else CTL=(ros2py control); fi

require_ros_domain real_ur.sh
require_number real_ur.sh --max-home-distance "$MAX_HOME_DISTANCE"
if ((DRY_RUN)); then
  cat <<STEPS
real_ur.sh --dry-run ($CONTROLLER): would
  1. read one /joint_states and refuse if any joint is > $MAX_HOME_DISTANCE rad from home
  2. ${CTL[*]} switch_controllers --activate $ACTIVATE --deactivate $DEACTIVATE --strict
  3. start scripts/tracker_usb.sh ${TRACKER_ARGS[*]:-} (USB camera -> /ball_state)
  4. start $EXE --ros-args --params-file $YAML ${CTRL_PARAMS[*]:-}
     (homes the arm smoothly, then balances once /ball_state is valid)
STEPS
  exit 0
fi
if ((! CONFIRMED)); then
  echo "real_ur.sh: refusing to start: this moves a real arm. Re-run with --i-know-the-arm-will-move" \
       "(or --dry-run to see the steps)." >&2
  exit 3
fi

echo "real_ur.sh: [1/4] checking the arm is near home" >&2
python - "$MAX_HOME_DISTANCE" <<'PY'
import sys, time
import numpy as np
import rclpy
from sensor_msgs.msg import JointState
from ball_balance.robot import HOME_POSITIONS_RAD, JOINT_NAMES

limit = float(sys.argv[1])
rclpy.init()
node = rclpy.create_node("real_ur_home_check")
got = []
node.create_subscription(JointState, "/joint_states", got.append, 10)
deadline = time.monotonic() + 10.0
while not got and time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.1)
if not got:
    sys.exit("real_ur.sh: no /joint_states within 10 s: is the UR driver running?")
index = {n: i for i, n in enumerate(got[0].name)}
missing = [n for n in JOINT_NAMES if n not in index]
if missing:
    sys.exit(f"real_ur.sh: /joint_states lacks {missing}")
q = np.array([got[0].position[index[n]] for n in JOINT_NAMES])
far = np.abs(q - np.array(HOME_POSITIONS_RAD))
if np.max(far) > limit:
    worst = JOINT_NAMES[int(np.argmax(far))]
    sys.exit(f"real_ur.sh: {worst} is {np.max(far):.2f} rad from home (limit {limit}); jog the arm closer first")
print(f"real_ur.sh: arm within {np.max(far):.3f} rad of home", file=sys.stderr)
PY

echo "real_ur.sh: [2/4] ${CTL[*]} switch_controllers --activate $ACTIVATE --deactivate $DEACTIVATE" >&2
"${CTL[@]}" switch_controllers --activate "$ACTIVATE" --deactivate "$DEACTIVATE" --strict

source "$ROOT/scripts/lib/stop_all.sh"
on_stopped() { echo "real_ur.sh: stopped; the arm holds its last commanded pose" >&2; }
trap stop_all INT TERM EXIT
echo "real_ur.sh: [3/4] tracker on the USB camera" >&2
"$ROOT/scripts/tracker_usb.sh" ${TRACKER_ARGS[@]+"${TRACKER_ARGS[@]}"} &
PIDS+=($!)
echo "real_ur.sh: [4/4] $EXE (homes first, then balances); Ctrl-C stops" >&2
"$EXE" --ros-args --params-file "$YAML" ${CTRL_PARAMS[@]+"${CTRL_PARAMS[@]}"} &
PIDS+=($!)
wait_any
