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
