#!/usr/bin/env bash
# The whole simulated balancing graph: MuJoCo UR arm in ros2_control_node + robot_state_publisher
# (scripts/sim_arm.sh), ball_tracker on the simulated camera, the balance controller (PID, MPC or policy)
# and the visualizer, each with its parameter file; a monitor prints progress once a second.
# Ctrl-C stops every process. Usually started through scripts/sim_pid.sh or scripts/sim_mpc.sh.
# The simulation waits, paused, until the nodes are up: the run starts with the ball at rest; the
# arm moves once the robot manager (docs/robot_manager.md) is configured and active, which the
# script does and reports, with every robot manager event (emergency stops included).
#
#   scripts/sim_balance.sh --controller pid                    # balance at the centre
#   scripts/sim_balance.sh --controller mpc --reference circle --radius 0.1 --period 10
#   scripts/sim_balance.sh --ball 0.08 -0.05 --domain noisy_vision --seed 2
#   scripts/sim_balance.sh --duration 30 --out artifacts/run    # stop after 30 s, plot + metrics
#   scripts/sim_balance.sh --duration 30 --out DIR --video-s 10 --debug-image   # + camera.mp4 with overlay
#   scripts/sim_balance.sh --truth-fed                          # no camera/tracker: /ball_state from truth
#   scripts/sim_balance.sh --param kp:=2.0                      # any controller parameter
#   scripts/sim_balance.sh --tracker-param disturbance_time_constant_s:=0.0   # any tracker parameter
#   scripts/sim_balance.sh --sim-param camera_rate_hz=60        # any simulation parameter (config/sim.yaml)
#   scripts/sim_balance.sh --force 2 90       # a constant force on the ball, as a plate 2 deg off level, towards +y
#   scripts/sim_balance.sh --plate-offset 2 0 # the plate mounted 2 deg off level about its x axis (rolls to -y)
#   scripts/sim_balance.sh --live-view-port 8081   # the live view's port (default 8080; 0: a free one)
#   scripts/sim_balance.sh --no-live-view          # without the live view in the browser
#
# The live view (docs/live_view.md) serves the run on http://127.0.0.1:8080/; the script prints
# the address once it listens. A live view that cannot start (port taken) is reported and the
# graph runs on without it.
#
# --force DEG [DIR_DEG]: F = m g sin(DEG) on the ball's centre towards DIR_DEG (plate axes, from +x
# towards +y; default 0), from the start; change it while running (docs/simulation.md):
#   ros2py service call /sim/set_ball_force ball_tracker_msgs/srv/SetBallForce \
#     "{ball_force_deg: 2.0, ball_force_dir_deg: 0.0}"
# --plate-offset DEG [AXIS_DEG]: the plate mounted DEG off level on the flange, turned about the
# horizontal plate axis at AXIS_DEG from +x (default 0); the ball rolls towards AXIS_DEG - 90.
# The domains force_1deg..force_3deg and off_level_2deg do the same as the benchmark's episodes.
#
# Exit code: the monitor's (0: the ball stayed on the plate, 1: it dropped), 3 when a node of
# the graph exited before the monitor (e.g. the controller manager died) or the robot manager
# could not be configured or activated (its reason is printed), 2 for bad arguments.
# Topics: /ball_state, /plate_cmd, /ball_reference, /ball_balance_visualization (RViz, frame
# plate_center), /forward_position_controller/commands (PID) or
# /scaled_joint_trajectory_controller/joint_trajectory (MPC), /joint_states, /tf, /sim/ball_truth.
# Change gains live: ros2 param set /ball_balance_controller kp 2.0 (or ros2py param set ...).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [[ -z "${BALL_BALANCE_ROOT:-}" ]]; then
  # shellcheck disable=SC1091
  source "$ROOT/env.sh"
fi

CONTROLLER=pid
REFERENCE=""
RADIUS=""
PERIOD=""
START_DELAY=""
BALL_X=0.08
BALL_Y=-0.05
DOMAIN=standard
SEED=0
DURATION=0
OUT=""
VIDEO_S=0
TRUTH_FED=0
DEBUG_IMAGE=false
CTRL_PARAMS=()
SIM_PARAMS=()
TRACKER_PARAMS=()
LIVE_VIEW=1
LIVE_VIEW_PORT="${BALL_BALANCE_LIVE_VIEW_PORT:-8080}"
usage() { sed -n '2,42p' "$0" | sed 's/^# \{0,1\}//'; }
# the optional second number of --force and --plate-offset (a negative angle is a number, not an option)
optional_number() { [[ -n "${1:-}" && "$1" != --* ]]; }
source "$ROOT/scripts/lib/args.sh"   # needs, require_*
while (($#)); do
  case "$1" in
    --controller) needs 1 "$@"; CONTROLLER="$2"; shift 2 ;;
    --reference) needs 1 "$@"; REFERENCE="$2"; shift 2 ;;
    --radius) needs 1 "$@"; RADIUS="$2"; shift 2 ;;
    --period) needs 1 "$@"; PERIOD="$2"; shift 2 ;;
    --start-delay) needs 1 "$@"; START_DELAY="$2"; shift 2 ;;
    --ball) needs 2 "$@"; BALL_X="$2"; BALL_Y="$3"; shift 3 ;;
    --domain) needs 1 "$@"; DOMAIN="$2"; shift 2 ;;
    --seed) needs 1 "$@"; SEED="$2"; shift 2 ;;
    --duration) needs 1 "$@"; DURATION="$2"; shift 2 ;;
    --out) needs 1 "$@"; OUT="$2"; shift 2 ;;
    --video-s) needs 1 "$@"; VIDEO_S="$2"; shift 2 ;;
    --truth-fed) TRUTH_FED=1; shift ;;
    --debug-image) DEBUG_IMAGE=true; shift ;;
    --param) needs 1 "$@"; CTRL_PARAMS+=(-p "$2"); shift 2 ;;
    --tracker-param) needs 1 "$@"; TRACKER_PARAMS+=(-p "$2"); shift 2 ;;
    --sim-param) needs 1 "$@"; SIM_PARAMS+=(--param "$2"); shift 2 ;;
    --live-view-port) needs 1 "$@"; LIVE_VIEW_PORT="$2"; shift 2 ;;
    --no-live-view) LIVE_VIEW=0; shift ;;
    --force)
      needs 1 "$@"; SIM_PARAMS+=(--param "ball_force_deg=$2"); shift 2
      if optional_number "${1:-}"; then SIM_PARAMS+=(--param "ball_force_dir_deg=$1"); shift; fi ;;
    --plate-offset)
      needs 1 "$@"; SIM_PARAMS+=(--param "plate_mount_tilt_deg=$2"); shift 2
      AXIS=0
      if optional_number "${1:-}"; then AXIS="$1"; shift; fi
      SIM_PARAMS+=(--param "plate_mount_axis_deg=$AXIS") ;;
    -h|--help) usage; exit 0 ;;
    *) echo "sim_balance.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
require_ros_domain sim_balance.sh
require_number sim_balance.sh --duration "$DURATION"
require_number sim_balance.sh --video-s "$VIDEO_S"
[[ -z "$RADIUS" ]] || require_number sim_balance.sh --radius "$RADIUS"
[[ -z "$PERIOD" ]] || require_number sim_balance.sh --period "$PERIOD"
[[ -z "$START_DELAY" ]] || require_number sim_balance.sh --start-delay "$START_DELAY"
require_port sim_balance.sh --live-view-port "$LIVE_VIEW_PORT"
[[ -z "$OUT" ]] || require_out_dir sim_balance.sh --out "$OUT"
case "$CONTROLLER" in
  # the controller the balance node commands, and the one that levels the plate at deactivate;
  # the live view's gains (the PID's are set at run time, the MPC's are shown, read-only)
  pid) EXE=ball_balance_controller; YAML="$ROOT/config/pid.yaml"; GAINS="[kp, ki, kd]"
       ARM_CONTROLLERS=(forward_position_controller scaled_joint_trajectory_controller) ;;
  mpc) EXE=ball_balance_mpc; YAML="$ROOT/config/mpc.yaml"; GAINS="[mpc_q_pos, mpc_q_vel, mpc_r_u]"
       ARM_CONTROLLERS=(scaled_joint_trajectory_controller forward_position_controller) ;;
  policy) EXE=ball_balance_policy; YAML="$ROOT/config/policy.yaml"; GAINS="[kp, ki, kd]"
       ARM_CONTROLLERS=(forward_position_controller scaled_joint_trajectory_controller) ;;
  *) echo "sim_balance.sh: --controller must be pid, mpc or policy, got '$CONTROLLER'" >&2; exit 2 ;;
esac
float() { [[ "$1" == *.* || "$1" == *e* ]] && echo "$1" || echo "$1.0"; }
[[ -n "$REFERENCE" ]] && CTRL_PARAMS+=(-p "reference_kind:=$REFERENCE")
[[ -n "$RADIUS" ]] && CTRL_PARAMS+=(-p "reference_radius_m:=$(float "$RADIUS")")
[[ -n "$PERIOD" ]] && CTRL_PARAMS+=(-p "reference_period_s:=$(float "$PERIOD")")
[[ -n "$START_DELAY" ]] && CTRL_PARAMS+=(-p "reference_start_delay_s:=$(float "$START_DELAY")")
VIS_PARAMS=()
[[ -n "$REFERENCE" ]] && VIS_PARAMS+=(-p "reference_kind:=$REFERENCE")
[[ -n "$RADIUS" ]] && VIS_PARAMS+=(-p "reference_radius_m:=$(float "$RADIUS")")
[[ -n "$PERIOD" ]] && VIS_PARAMS+=(-p "reference_period_s:=$(float "$PERIOD")")

SIM_CONFIG="$ROOT/config/sim.yaml"
((TRUTH_FED)) && SIM_CONFIG="$ROOT/config/sim_truth_fed.yaml"
SIM_ARGS=(--sim-config "$SIM_CONFIG" --domain "$DOMAIN" --seed "$SEED" --param "ball_x=$BALL_X" --param "ball_y=$BALL_Y"
          --param start_paused=true --managed ${SIM_PARAMS[@]+"${SIM_PARAMS[@]}"})
# a bad controller, tracker or simulation parameter (--param kp:=abc, --force 20, ...) or another
# graph on this ROS domain: its one line, before anything starts (the checks run side by side)
# joint_states_timeout_s 5 s (1 s for a real arm): on a loaded 2-core machine the controller saw
# /joint_states gaps of 1.0-2.3 s wall time from a live manager
CONTROLLER_ARGS=(--params-file "$YAML" -p use_sim_time:=true -p joint_states_timeout_s:=5.0)
TRACKER_ARGS=(--params-file "$ROOT/config/ball_tracker.yaml" -p use_sim_time:=true -p "publish_debug_image:=$DEBUG_IMAGE")
CHECKS=()
check_node_params "$EXE" "${CONTROLLER_ARGS[@]}" ${CTRL_PARAMS[@]+"${CTRL_PARAMS[@]}"} &
CHECKS+=($!)
if ((! TRUTH_FED)); then
  check_node_params ball_tracker "${TRACKER_ARGS[@]}" ${TRACKER_PARAMS[@]+"${TRACKER_PARAMS[@]}"} &
  CHECKS+=($!)
fi
"$ROOT/scripts/sim_arm.sh" --check-params "${SIM_ARGS[@]}" &
CHECKS+=($!)
CHECKED=0
for pid in "${CHECKS[@]}"; do wait "$pid" || CHECKED=2; done
((CHECKED == 0)) || exit 2
export SIM_ARM_DOMAIN_CHECKED=1
LOGS="$(mktemp -d "${TMPDIR:-/tmp}/ball_balance_graph.XXXXXX")"
source "$ROOT/scripts/lib/stop_all.sh"
source "$ROOT/scripts/lib/graph.sh"
source "$ROOT/scripts/lib/realtime.sh"
realtime_for 4   # the controller manager's loop and executor, the tracker, the controller
RT_OFF=()
((REALTIME)) || RT_OFF=(-p thread_priority:=0)
on_stopped() { echo "sim_balance.sh: stopped (logs in $LOGS)" >&2; }
trap stop_all INT TERM EXIT

echo "sim_balance.sh: $CONTROLLER controller, domain $DOMAIN seed $SEED, ball released at ($BALL_X, $BALL_Y) m; logs in $LOGS" >&2
start sim "$ROOT/scripts/sim_arm.sh" "${SIM_ARGS[@]}"
if ((! TRUTH_FED)); then
  start tracker ball_tracker --ros-args "${TRACKER_ARGS[@]}" ${RT_OFF[@]+"${RT_OFF[@]}"} \
    ${TRACKER_PARAMS[@]+"${TRACKER_PARAMS[@]}"}
fi
start controller "$EXE" --ros-args "${CONTROLLER_ARGS[@]}" ${RT_OFF[@]+"${RT_OFF[@]}"} ${CTRL_PARAMS[@]+"${CTRL_PARAMS[@]}"}
start visualizer ball_balance_visualizer --ros-args -p use_sim_time:=true ${VIS_PARAMS[@]+"${VIS_PARAMS[@]}"}
# the arm moves once the robot manager is active: resume_when configures and activates it
ROBOT_MANAGER=1
ROBOT_MANAGER_CONTROLLERS="${ARM_CONTROLLERS[0]}"
# shellcheck disable=SC2046
start robot_manager robot_manager --ros-args $(robot_manager_params "${ARM_CONTROLLERS[1]}")
start events show_events
if ((LIVE_VIEW)); then
  LIVE_IMAGE=/camera/image_raw
  [[ "$DEBUG_IMAGE" == true ]] && LIVE_IMAGE=/ball_tracker/debug_image
  start_live_view "$LIVE_VIEW_PORT" -p "controller_node:=$EXE" -p "gain_names:=$GAINS" -p "image_topic:=$LIVE_IMAGE"
fi
# the simulation starts paused: it runs once the tracker (or the truth feed), the controller and
# the monitor are up
start resume resume_when /ball_state=Publisher /plate_cmd=Publisher /sim/ball_truth=Subscription

MONITOR=(python -m ball_balance.benchmark.live --sim-time --duration "$DURATION" --title "$CONTROLLER, $DOMAIN")
[[ -n "$OUT" ]] && MONITOR+=(--out "$OUT")
[[ "$VIDEO_S" != 0 ]] && MONITOR+=(--video-s "$VIDEO_S")
[[ "$DEBUG_IMAGE" == true ]] && MONITOR+=(--video-topic /ball_tracker/debug_image)
run_monitor "${MONITOR[@]}"
