#!/usr/bin/env bash
# The simulated UR arm: ros2_control_node hosting ball_balance/MujocoSystem (MuJoCo arm +
# plate + ball + overhead camera) with config/ur_controllers.yaml, plus robot_state_publisher.
# joint_state_broadcaster and forward_position_controller come up active (with
# --trajectory: scaled_joint_trajectory_controller instead). Ctrl-C stops everything.
#
#   scripts/sim_arm.sh                              # standard domain, camera rate and size of config/sim.yaml
#   scripts/sim_arm.sh --domain slippery --seed 3   # an evaluation domain (docs/design.md section 7)
#   scripts/sim_arm.sh --sim-config config/sim_truth_fed.yaml   # no camera, /ball_state from truth
#   scripts/sim_arm.sh --param camera_rate_hz=30 --param camera_width=320 --param camera_height=240
#   scripts/sim_arm.sh --trajectory                 # MPC-style: the trajectory controller active
#   scripts/sim_arm.sh --managed                    # for the robot manager: hardware inactive, only
#                                                   # joint_state_broadcaster active (nothing moves)
#   scripts/sim_arm.sh --check-params --param ball_force_deg=2   # only check the parameters and that
#                                                   # the ROS domain is free: exit 0, or 2
#
# Topics: /joint_states, /tf, /tf_static, /robot_description, /camera/image_raw,
# /camera/camera_info, /sim/ball_truth, /sim/ball_dropped, /clock; services /sim/reset_ball,
# /sim/set_ball_force and more (docs/simulation.md).
# See the camera without a display:
#   camera_snapshot --ros-args -p png:=/tmp/camera.png -p mp4:=/tmp/camera.mp4 -p duration_s:=5.0
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [[ -z "${BALL_BALANCE_ROOT:-}" ]]; then
  # shellcheck disable=SC1091
  source "$ROOT/env.sh"
fi

SIM_CONFIG="$ROOT/config/sim.yaml"
CONTROLLERS="$ROOT/config/ur_controllers.yaml"
PARAMS=()
TRAJECTORY=0
CHECK_ONLY=0
MANAGED=0
usage() { sed -n '2,21p' "$0" | sed 's/^# \{0,1\}//'; }
source "$ROOT/scripts/lib/args.sh"   # needs, require_*
while (($#)); do
  case "$1" in
    --sim-config) needs 1 "$@"; SIM_CONFIG="$(realpath -m -- "$2")"; shift 2 ;;
    --controllers) needs 1 "$@"; CONTROLLERS="$(realpath -m -- "$2")"; shift 2 ;;
    --domain) needs 1 "$@"; PARAMS+=(--param "domain=$2"); shift 2 ;;
    --seed) needs 1 "$@"; PARAMS+=(--param "seed=$2"); shift 2 ;;
    --param) needs 1 "$@"; PARAMS+=(--param "$2"); shift 2 ;;
    --trajectory) TRAJECTORY=1; shift ;;
    --managed) MANAGED=1; shift ;;
    --check-params) CHECK_ONLY=1; shift ;;
    -h|--help) usage; exit 0 ;;
    *) echo "sim_arm.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
[[ -f "$SIM_CONFIG" ]] || { echo "sim_arm.sh: no such sim config: $SIM_CONFIG" >&2; exit 2; }
require_ros_domain sim_arm.sh
require_params_file sim_arm.sh --controllers "$CONTROLLERS"

WORK="$(mktemp -d "${TMPDIR:-/tmp}/ball_balance_sim.XXXXXX")"
URDF="$WORK/ur5e_ball_balance_sim.urdf"
# the description with the MuJoCo hardware selected and its parameters (the world is built
# from this same file: robot_description_file points at it)
python -m ball_balance.robot --hardware mujoco --param "sim_config=$SIM_CONFIG" \
  --param "robot_description_file=$URDF" ${PARAMS[@]+"${PARAMS[@]}"} >"$URDF" || { rm -rf "$WORK"; exit 2; }
# bad parameters: one clear line before anything starts
python -m ball_balance.hardware.mujoco_system --check "$URDF" || { rm -rf "$WORK"; exit 2; }
# Another graph on this ROS domain (a second terminal, a bag played with --clock, an arm's
# driver) would drive this arm and be driven by it: one clear line instead. A simulation on
# this machine holds a lock on its domain for as long as any of its processes runs (they
# inherit it), so a second one is refused whatever the load. What is not ours is looked for
# by discovery, which gets 3 s: a graph that answers later than that is not caught. The
# graph scripts check with --check-params before they start anything and set
# SIM_ARM_DOMAIN_CHECKED=1 (the lock is still taken).
DOMAIN_ID="${ROS_DOMAIN_ID:-0}"
refuse_domain() {
  echo "sim_arm.sh: ROS_DOMAIN_ID=$DOMAIN_ID is taken: $1; stop it, or run this graph on a domain" \
    "of its own (export ROS_DOMAIN_ID=$(((DOMAIN_ID + 1) % 233)))" >&2
  rm -rf "$WORK"
  exit 2
}
DOMAIN_LOCK="/tmp/ball_balance-domain-$DOMAIN_ID-uid$(id -u).lock"
exec {DOMAIN_LOCK_FD}>>"$DOMAIN_LOCK"
flock -n "$DOMAIN_LOCK_FD" ||
  refuse_domain "a simulation on this machine runs on it (sim_arm.sh pid $(cat "$DOMAIN_LOCK"), or a process it started)"
echo "$$" >"$DOMAIN_LOCK"
if [[ -z "${SIM_ARM_DOMAIN_CHECKED:-}" ]]; then
  (timeout -k 5 30 ros2py topic info /clock --spin-time 3 >"$WORK/clock.txt" 2>/dev/null || true) &
  (timeout -k 5 30 ros2py node list --spin-time 3 >"$WORK/nodes.txt" 2>/dev/null || true) &
  wait
  TAKEN=""
  CLOCKS="$(sed -n 's/^Publisher count: //p' "$WORK/clock.txt")"
  ((${CLOCKS:-0} > 0)) && TAKEN="/clock has ${CLOCKS} publisher(s)"
  grep -qx /controller_manager "$WORK/nodes.txt" && TAKEN="${TAKEN:+$TAKEN and }/controller_manager is running"
  [[ -z "$TAKEN" ]] || refuse_domain "$TAKEN (another simulation, a bag played with --clock or an arm's driver)"
fi

((CHECK_ONLY)) && { rm -rf "$WORK"; exit 0; }

HW_STATE=()
if ((MANAGED)); then
  # start-up for the robot manager (docs/robot_manager.md): the hardware configured (physics, camera
  # and clock run; nothing is written to the servos, which hold home) and no controller that
  # moves the arm active; the robot manager's activate switches them on together
  ACTIVE="[joint_state_broadcaster]"
  INACTIVE="[forward_position_controller, scaled_joint_trajectory_controller]"
  HW_STATE=(-p "hardware_components_initial_state.inactive:=[ur5e_ball_balance]")
elif ((TRAJECTORY)); then
  ACTIVE="[joint_state_broadcaster, scaled_joint_trajectory_controller]"
  INACTIVE="[forward_position_controller]"
else
  ACTIVE="[joint_state_broadcaster, forward_position_controller]"
  INACTIVE="[scaled_joint_trajectory_controller]"
fi

source "$ROOT/scripts/lib/stop_all.sh"
source "$ROOT/scripts/lib/realtime.sh"
realtime_for 2   # the controller manager's loop and executor (a slow machine keeps both busy)
MANAGER_RT=()
((REALTIME)) || MANAGER_RT=(-p thread_priority:=0 -p loop.executor_thread_priority:=0)
on_stopped() { rm -rf "$WORK"; }
trap stop_all INT TERM EXIT

robot_state_publisher --ros-args -p "robot_description_file:=$URDF" &
PIDS+=($!)
# config/sim_manager.yaml: the simulated arm's scheduling (why: in that file)
ros2_control_node --ros-args --params-file "$CONTROLLERS" --params-file "$ROOT/config/sim_manager.yaml" \
  -p "robot_description_file:=$URDF" ${MANAGER_RT[@]+"${MANAGER_RT[@]}"} \
  -p "activate_controllers:=$ACTIVE" -p "inactive_controllers:=$INACTIVE" ${HW_STATE[@]+"${HW_STATE[@]}"} &
PIDS+=($!)
echo "sim_arm.sh: running (robot_state_publisher ${PIDS[0]}, ros2_control_node ${PIDS[1]}); Ctrl-C stops" >&2
# exit when either process ends (then stop the other)
wait_any
