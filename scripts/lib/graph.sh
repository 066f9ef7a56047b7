# Sourced (after scripts/lib/stop_all.sh) by the scripts that run a whole graph with a
# monitor (sim_balance.sh, sim_policy_in_manager.sh). They set LOGS, start each node with
# `start NAME CMD...` and end with `run_monitor CMD...`.
NAMES=()

start() {  # start NAME CMD...: in the background, output to $LOGS/NAME.log
  local name="$1"; shift
  "$@" >"$LOGS/$name.log" 2>&1 &
  PIDS+=($!)
  NAMES+=("$name")
  echo "$(basename "$0"): started $name (pid $!)" >&2
}

# fd 3: the script's own stderr, for lines from helper processes (`start` sends their output
# to their log)
exec 3>&2

# The graph scripts start the simulation paused (start_paused=true): while the nodes come up,
# a domain's push or a plate out of level would move the ball before any controller acts.
# `start resume resume_when TOPIC=Publisher|Subscription ...` waits until each topic has one,
# resumes the simulation, then idles as a process of the graph (a timeout ends the graph).
wait_for_endpoint() {  # wait_for_endpoint TOPIC Publisher|Subscription: up to 120 s
  local info _
  for _ in $(seq 240); do
    info="$(ros2py topic info "$1" 2>/dev/null || true)"
    [[ "$info" == *"$2 count: "[1-9]* ]] && return 0
    sleep 0.5
  done
  echo "$(basename "$0"): no ${2,,} on $1 after 120 s" >&3
  return 1
}
resume_when() {
  local spec
  for spec in "$@"; do wait_for_endpoint "${spec%=*}" "${spec#*=}" || return 3; done
  # a manager that dies between the topics and the call would leave it waiting forever
  ros2py service call --timeout 30 /sim/set_pause std_srvs/srv/SetBool "{data: false}" || return 3
  echo "$(basename "$0"): simulation resumed (the graph is up)" >&3
  exec sleep infinity
}

# The monitor ends the run (after its --duration, or never); any other process ending first
# is a dead core node: the script exits there with code 3 and that process's last log lines.
# Ctrl-C exits with 130 (stop_all has already stopped everything).
run_monitor() {  # run_monitor CMD...: never returns
  set +e
  "$@" &
  local monitor=$!
  PIDS+=("$monitor")
  local ended code
  wait -n -p ended "${PIDS[@]}"   # until Ctrl-C or a process ends
  code=$?
  ((STOPPING)) && exit 130
  if [[ "${ended:-}" != "$monitor" ]]; then
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
