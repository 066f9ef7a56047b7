# Sourced (after scripts/lib/stop_all.sh) by the scripts that run a whole graph with a
# monitor (sim_balance.sh, sim_policy_in_manager.sh). They set LOGS, start each node with
# `start NAME CMD...` and end with `run_monitor CMD...`.
NAMES=()

start() {  # start NAME CMD...: in the background, output to $LOGS/NAME.log
  # a Ctrl-C during the start-up: stop_all has stopped what had started, and the script goes on
  # after it (a trap returns): nothing more is started, the script ends there
  ((STOPPING)) && exit 130
  local name="$1"; shift
  "$@" >"$LOGS/$name.log" 2>&1 &
  PIDS+=($!)
  NAMES+=("$name")
  echo "$(basename "$0"): started $name (pid $!)" >&2
}

# `start NAME optional CMD...`: a node the graph can do without (the live view). When it exits
# (its port taken, say), one line says so, with the last line of its log (its reason), and the
# graph goes on: the process left in its place idles, so that run_monitor does not take it for
# a dead core node.
optional() {
  local status=0 why
  "$@" || status=$?
  why="$(tail -n 1 "$(readlink "/proc/$BASHPID/fd/2")" 2>/dev/null || true)"
  ((STOPPING)) || echo "$(basename "$0"): $(basename "$1") exited (status $status${why:+: $why});" \
    "the graph goes on without it" >&3
  exec sleep infinity
}

# `start NAME announce_url LOG WHAT`: print the first http:// address LOG names, once it does
# (up to 120 s), so the user learns where the live view listens (its port may be chosen at
# start-up); then idle as a process of the graph, which stop_all ends with the script (a loop
# left in the background would outlive it, holding the script's stderr open).
announce_url() {
  local log="$1" what="$2" i url
  for ((i = 0; i < 1200; i++)); do
    url="$(grep -o -m1 'http://[^ ]*' "$log" 2>/dev/null || true)"
    if [[ -n "$url" ]]; then
      echo "$(basename "$0"): $what: $url" >&3
      break
    fi
    sleep 0.1
  done
  exec sleep infinity
}

# start_live_view PORT ARGS...: the live view in the browser (docs/live_view.md) as an optional
# node with `--ros-args -p port:=PORT ARGS...`; its address is printed once it listens.
start_live_view() {
  local port="$1"; shift
  start live_view optional ball_balance_live_view --ros-args -p "port:=$port" "$@"
  start live_view_url announce_url "$LOGS/live_view.log" "live view (open it in a browser)"
}

# fd 3: the script's own stderr, for lines from helper processes (`start` sends their output
# to their log)
exec 3>&2

# Each ros2py call runs under `timeout`: one that hangs (rclpy's teardown has, for minutes)
# must not hold the start-up. A call gets ROS2PY_TIMEOUT_S (SIGTERM, SIGKILL 5 s later); a
# discovery call takes up to about 7 s on a loaded machine.
ROS2PY_TIMEOUT_S="${ROS2PY_TIMEOUT_S:-20}"
ros2py_bounded() {  # ros2py_bounded SECONDS ARGS...: `ros2py ARGS...`, ended after SECONDS (status 124 or 137)
  local seconds="$1"; shift
  timeout -k 5 "$seconds" ros2py "$@"
}

# The graph scripts start the simulation paused (start_paused=true): while the nodes come up,
# a domain's push or a plate out of level would move the ball before any controller acts.
# `start resume resume_when TOPIC=Publisher|Subscription ...` waits until each topic has one,
# resumes the simulation, then idles as a process of the graph (a timeout ends the graph).
wait_for_endpoint() {  # wait_for_endpoint TOPIC Publisher|Subscription [SECONDS]: up to SECONDS (120)
  local topic="$1" kind="$2" limit="${3:-120}"
  local end=$((SECONDS + limit)) left info status=0
  while ((left = end - SECONDS, left > 0)); do
    status=0
    info="$(ros2py_bounded $((left < ROS2PY_TIMEOUT_S ? left : ROS2PY_TIMEOUT_S)) topic info "$topic" 2>/dev/null)" \
      || status=$?
    [[ "$info" == *"$kind count: "[1-9]* ]] && return 0
    sleep 0.5
  done
  local hung=""
  ((status == 124 || status == 137)) && hung=" (the last \`ros2py topic info $topic\` did not answer in time)"
  echo "$(basename "$0"): no ${kind,,} on $topic after $limit s$hung" >&3
  return 1
}
resume_when() {
  local spec
  for spec in "$@"; do wait_for_endpoint "${spec%=*}" "${spec#*=}" || return 3; done
  if ((ROBOT_MANAGER)); then
    wait_for_endpoint /robot_manager/events Publisher || return 3
    bring_up || return 3
  fi
  # a manager that dies between the topics and the call would leave it waiting forever
  if ! ros2py_bounded 60 service call --timeout 30 /sim/set_pause std_srvs/srv/SetBool "{data: false}"; then
    echo "$(basename "$0"): the simulation was not resumed: the call to /sim/set_pause failed or timed out" >&3
    return 3
  fi
  echo "$(basename "$0"): simulation resumed (the graph is up)" >&3
  exec sleep infinity
}

# The robot manager (docs/robot_manager.md) is how the arm starts moving: the simulated arm comes
# up with nothing that moves it active (sim_arm.sh --managed), and `bring_up` configures and then
# activates /robot_manager, printing each outcome (a failure: its reason, status 3). It runs
# before the simulation resumes, so the controller takes over at simulated time 0 whatever the
# machine's speed (lock-step: the same run on a slow machine as on a fast one); a paused
# simulation renders no frames, so configure does not wait for the camera here
# (camera_required:=false; its camera-lost watchdog runs once frames flow).
# Deadlines grow with the machine's load (LOAD_FACTOR: the 1-minute load average per CPU, at
# least 1).
ROBOT_MANAGER=0
ROBOT_MANAGER_CONTROLLERS=""   # the balancing controller(s) it activates, comma-separated
LOAD_FACTOR="$(awk -v cpus="$(nproc)" '{f = $1 / cpus; printf "%d", (f > 1 ? f + 0.999 : 1)}' /proc/loadavg)"
ROBOT_MANAGER_TIMEOUT_S="${ROBOT_MANAGER_TIMEOUT_S:-$((60 * LOAD_FACTOR))}"
robot_manager_params() {  # robot_manager_params LEVEL_CONTROLLER: its -p arguments
  echo "-p controllers:=[$ROBOT_MANAGER_CONTROLLERS] -p level_controller:=$1 -p camera_required:=false"
}
bring_up() {
  local label out why
  for label in configure activate; do
    if ! out="$(ros2py_bounded "$((ROBOT_MANAGER_TIMEOUT_S + 40 * LOAD_FACTOR))" lifecycle set /robot_manager \
        "$label" --timeout "$ROBOT_MANAGER_TIMEOUT_S" --spin-time "$((30 * LOAD_FACTOR))" 2>&1)"; then
      why="$(grep -h "$label failed" "$LOGS/robot_manager.log" | tail -n 1 | sed 's/.*\]: //')"
      echo "$(basename "$0"): robot_manager: ${why:-$label failed: ${out//$'\n'/ }}" >&3
      return 3
    fi
    echo "$(basename "$0"): robot_manager: $label done" >&3
  done
  echo "$(basename "$0"): robot_manager active: $ROBOT_MANAGER_CONTROLLERS active with the hardware (emergency stop:" \
    "ros2py service call /robot_manager/emergency_stop std_srvs/srv/Trigger)" >&3
}
# every event of the robot manager (stops, transitions) on the script's stderr, as it happens
show_events() {
  ros2py topic echo /robot_manager/events diagnostic_msgs/msg/DiagnosticStatus --field message \
    --qos-durability transient_local --qos-reliability reliable 2>/dev/null \
    | grep --line-buffered -v '^---$' | sed -u "s/^'\(.*\)'$/\1/; s/^/$(basename "$0"): robot_manager event: /" >&3
  exec sleep infinity
}

# The monitor ends the run (after its --duration, or never); any other process ending first
# is a dead core node: the script exits there with code 3 and that process's last log lines.
# Ctrl-C exits with 130 (stop_all has already stopped everything).
run_monitor() {  # run_monitor CMD...: never returns
  set +e
  ((STOPPING)) && exit 130
  "$@" &
  local monitor=$!
  PIDS+=("$monitor")
  local code
  wait_any   # until Ctrl-C or a process ends
  code=$?
  ((STOPPING)) && exit 130
  if [[ "$ENDED" != "$monitor" ]]; then
    code=3
    local i
    for i in "${!NAMES[@]}"; do
      if ! kill -0 "${PIDS[$i]}" 2>/dev/null; then
        echo "$(basename "$0"): ${NAMES[$i]} exited; stopping the graph. Last lines of its log:" >&2
        tail -n 5 "$LOGS/${NAMES[$i]}.log" >&2
      fi
    done
  fi
  exit "$code"
}
