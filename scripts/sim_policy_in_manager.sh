#!/usr/bin/env bash
# The ball balanced inside the simulated arm's controller manager: MuJoCo UR arm in
# ros2_control_node (scripts/sim_arm.sh) + ball_tracker on the simulated camera, and
# ball_balance_controller (ball_balance_controllers/BallBalanceController, the learned policy by
# default, config/ur_controllers_policy.yaml) active in the manager instead of
# forward_position_controller (both claim the six joints' position commands), activated with the
# hardware by the robot manager (docs/robot_manager.md). No balance node: /ball_state goes straight
# into the manager. A monitor prints progress once a second; robot manager events are printed.
#
#   scripts/sim_policy_in_manager.sh
#   scripts/sim_policy_in_manager.sh --ball 0.08 -0.05 --domain full_dr --seed 2 --duration 30
#   scripts/sim_policy_in_manager.sh --tilt-law mpc --params-file my_values.yaml   # another law, its values
#   scripts/sim_policy_in_manager.sh --reference circle --radius 0.1 --period 10 --duration 20
#   scripts/sim_policy_in_manager.sh --truth-fed           # no camera/tracker: /ball_state from truth
#   scripts/sim_policy_in_manager.sh --tracker-param disturbance_time_constant_s:=0.0   # any tracker parameter
#   scripts/sim_policy_in_manager.sh --live-view-port 8081  # the live view's port (8080; --no-live-view: none)
#
# The live view (docs/live_view.md) shows the run on http://127.0.0.1:8080/ (the address is
# printed); the controller runs in the manager, so the page shows no controller node and gains.
#
# Exit code: the monitor's (0: the ball stayed on the plate, 1: it dropped), 3 when a process of
# the graph (or the controller's spawning) failed first, 2 for bad arguments.
# See the controller: ros2py control list_controllers; its counters on
# /controller_manager/introspection_data (ball_balance_controller.refused_*) and /diagnostics.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [[ -z "${BALL_BALANCE_ROOT:-}" ]]; then
  # shellcheck disable=SC1091
  source "$ROOT/env.sh"
fi

CONTROLLER=ball_balance_controller
PARAMS_FILE="$ROOT/config/ur_controllers_policy.yaml"
TILT_LAW=""
BALL_X=0.08
BALL_Y=-0.05
DOMAIN=standard
SEED=0
DURATION=0
OUT=""
TRUTH_FED=0
LIVE_VIEW=1
LIVE_VIEW_PORT="${BALL_BALANCE_LIVE_VIEW_PORT:-8080}"
REFERENCE=""
RADIUS=""
PERIOD=""
TRACKER_PARAMS=()
usage() { sed -n '2,24p' "$0" | sed 's/^# \{0,1\}//'; }
source "$ROOT/scripts/lib/args.sh"   # needs, require_*
while (($#)); do
  case "$1" in
    --tilt-law) needs 1 "$@"; TILT_LAW="$2"; shift 2 ;;
    --params-file) needs 1 "$@"; PARAMS_FILE="$(realpath -m -- "$2")"; shift 2 ;;
    --reference) needs 1 "$@"; REFERENCE="$2"; shift 2 ;;
    --radius) needs 1 "$@"; RADIUS="$2"; shift 2 ;;
    --period) needs 1 "$@"; PERIOD="$2"; shift 2 ;;
    --ball) needs 2 "$@"; BALL_X="$2"; BALL_Y="$3"; shift 3 ;;
    --domain) needs 1 "$@"; DOMAIN="$2"; shift 2 ;;
    --seed) needs 1 "$@"; SEED="$2"; shift 2 ;;
    --duration) needs 1 "$@"; DURATION="$2"; shift 2 ;;
    --out) needs 1 "$@"; OUT="$2"; shift 2 ;;
    --truth-fed) TRUTH_FED=1; shift ;;
    --tracker-param) needs 1 "$@"; TRACKER_PARAMS+=(-p "$2"); shift 2 ;;
    --live-view-port) needs 1 "$@"; LIVE_VIEW_PORT="$2"; shift 2 ;;
    --no-live-view) LIVE_VIEW=0; shift ;;
    -h|--help) usage; exit 0 ;;
    *) echo "sim_policy_in_manager.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
require_ros_domain sim_policy_in_manager.sh
require_number sim_policy_in_manager.sh --duration "$DURATION"
[[ -z "$RADIUS" ]] || require_number sim_policy_in_manager.sh --radius "$RADIUS"
[[ -z "$PERIOD" ]] || require_number sim_policy_in_manager.sh --period "$PERIOD"
require_port sim_policy_in_manager.sh --live-view-port "$LIVE_VIEW_PORT"
[[ -z "$OUT" ]] || require_out_dir sim_policy_in_manager.sh --out "$OUT"
require_params_file sim_policy_in_manager.sh --params-file "$PARAMS_FILE"
case "${TILT_LAW:-policy}" in
  policy|pid|mpc) ;;
  *) echo "sim_policy_in_manager.sh: --tilt-law must be policy, pid or mpc, got '$TILT_LAW'" >&2; exit 2 ;;
esac

SIM_CONFIG="$ROOT/config/sim.yaml"
((TRUTH_FED)) && SIM_CONFIG="$ROOT/config/sim_truth_fed.yaml"
LOGS="$(mktemp -d "${TMPDIR:-/tmp}/ball_balance_graph.XXXXXX")"
source "$ROOT/scripts/lib/realtime.sh"
realtime_for 3 --later   # the manager's loop (the controller's step worker shares its CPU), executor, tracker
RT_OFF=()
STEP_PRIORITY=""
((REALTIME)) || { RT_OFF=(-p thread_priority:=0); STEP_PRIORITY=0; }
if [[ -n "$TILT_LAW$REFERENCE$RADIUS$PERIOD$STEP_PRIORITY" ]]; then
  # the controller's node takes one parameter file: the chosen one with these values replaced
  # (checked by the controller's schema at configure)
  python - "$PARAMS_FILE" "$CONTROLLER" "tilt_law=$TILT_LAW" "reference_kind=$REFERENCE" \
    "reference_radius_m=$RADIUS" "reference_period_s=$PERIOD" "step_thread_priority=$STEP_PRIORITY" \
    >"$LOGS/controller_params.yaml" <<'EOF' || exit 2
import sys, yaml
path, name, *changes = sys.argv[1:]
values = yaml.safe_load(open(path))   # a mapping: checked above
section = values.setdefault(name, {})
if not isinstance(section, dict) or not isinstance(section.setdefault("ros__parameters", {}), dict):
    sys.exit(f"sim_policy_in_manager.sh: --params-file: '{path}': {name} must be {{ros__parameters: {{...}}}}")
for change in changes:
    key, _, text = change.partition("=")
    if text:
        section["ros__parameters"][key] = (text if key in ("tilt_law", "reference_kind")
                                           else int(text) if key == "step_thread_priority" else float(text))
yaml.safe_dump(values, sys.stdout)
EOF
  PARAMS_FILE="$LOGS/controller_params.yaml"
fi
SIM_ARGS=(--sim-config "$SIM_CONFIG" --domain "$DOMAIN" --seed "$SEED" --param "ball_x=$BALL_X" --param "ball_y=$BALL_Y"
          --param start_paused=true --managed)
# a bad simulation or controller parameter, or another graph on this ROS domain: its one line,
# before anything starts. The controller is loaded and configured as the start will (its
# parameters, its model, the interfaces it claims) in a manager of its own on the mock arm.
python -m ball_balance.robot --hardware mock >"$LOGS/check_arm.urdf"
check_node_params ros2_control_node --params-file "$ROOT/config/ur_controllers.yaml" \
  -p "robot_description_file:=$LOGS/check_arm.urdf" -p "activate_controllers:=[joint_state_broadcaster]" \
  -p "inactive_controllers:=[forward_position_controller, scaled_joint_trajectory_controller, $CONTROLLER]" \
  -p "$CONTROLLER.type:=ball_balance_controllers/BallBalanceController" -p "$CONTROLLER.params_file:=$PARAMS_FILE" &
CONTROLLER_CHECK=$!
"$ROOT/scripts/sim_arm.sh" --check-params "${SIM_ARGS[@]}" || { wait "$CONTROLLER_CHECK" || true; exit 2; }
wait "$CONTROLLER_CHECK" || exit 2
echo "$REALTIME_NOTE" >&2
export SIM_ARM_DOMAIN_CHECKED=1
source "$ROOT/scripts/lib/stop_all.sh"
source "$ROOT/scripts/lib/graph.sh"
on_stopped() { echo "sim_policy_in_manager.sh: stopped (logs in $LOGS)" >&2; }
trap stop_all INT TERM EXIT

echo "sim_policy_in_manager.sh: ${TILT_LAW:-policy} tilt law in the controller manager, domain $DOMAIN seed $SEED," \
  "ball released at ($BALL_X, $BALL_Y) m; logs in $LOGS" >&2
start sim "$ROOT/scripts/sim_arm.sh" "${SIM_ARGS[@]}"
if ((! TRUTH_FED)); then
  start tracker ball_tracker --ros-args --params-file "$ROOT/config/ball_tracker.yaml" -p use_sim_time:=true \
    ${RT_OFF[@]+"${RT_OFF[@]}"} ${TRACKER_PARAMS[@]+"${TRACKER_PARAMS[@]}"}
fi
if ((LIVE_VIEW)); then
  start_live_view "$LIVE_VIEW_PORT"
fi
# load and configure (the model is checked here: a misfit fails with one line)
if ! spawner "$CONTROLLER" -t ball_balance_controllers/BallBalanceController -p "$PARAMS_FILE" --inactive \
    --controller-manager-timeout 120 --service-call-timeout 60 >"$LOGS/spawner.log" 2>&1; then
  ((STOPPING)) && exit 130   # Ctrl-C: the spawner was stopped with the graph
  echo "sim_policy_in_manager.sh: could not load $CONTROLLER:" >&2
  tail -n 5 "$LOGS/spawner.log" >&2
  grep -h "$CONTROLLER" "$LOGS/sim.log" | tail -n 5 >&2 || true
  exit 3
fi
# the robot manager activates it with the hardware (forward_position_controller stays inactive:
# sim_arm.sh --managed), once the monitor listens (it counts from the engagement) and the
# simulation (paused until then) has resumed with /ball_state's publisher up. The bring-up stays
# a process of the graph (a failed configure or activate ends the graph with its reason, exit code 3).
ROBOT_MANAGER=1
ROBOT_MANAGER_CONTROLLERS="$CONTROLLER"
# shellcheck disable=SC2046
start robot_manager robot_manager --ros-args $(robot_manager_params scaled_joint_trajectory_controller)
start events show_events
bring_up_when_watched() {
  wait_for_endpoint /ball_reference Subscription || return 3
  resume_when /ball_state=Publisher
}
start handover bring_up_when_watched

MONITOR=(python -m ball_balance.benchmark.live --sim-time --duration "$DURATION"
         --title "${TILT_LAW:-policy} in the manager, $DOMAIN${REFERENCE:+, $REFERENCE}")
[[ -n "$OUT" ]] && MONITOR+=(--out "$OUT")
run_monitor "${MONITOR[@]}"
