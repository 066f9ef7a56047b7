# Sourced by the scripts that compose a graph. They start each node in the background,
# append its pid to PIDS, and `trap stop_all INT TERM EXIT`. stop_all sends SIGTERM to every
# one (background jobs of a script ignore SIGINT; every node shuts down cleanly on SIGTERM),
# waits up to 6 s for each, SIGKILLs what is left, then runs the script's `on_stopped` if
# it defines one. A second Ctrl-C while it stops does not cut the stop short (the nodes
# ignore further signals while they shut down, controller_manager_py/controller_manager_py/ros/node_main.py): it is
# answered with one line, and whatever has not stopped 6 s after the first is killed.
#
# What the started processes have started in turn (a helper's `ros2py service call`, the
# manager's camera renderer) is stopped the same way once its parent has ended: those
# children are noted before the stop. Otherwise a child whose parent died on SIGTERM in the
# middle of a command (a shell function in the background) would outlive the script, waiting
# on a service that is gone.
PIDS=()
STOPPING=0
descendants() {  # descendants PID...: every process below them
  local pid child
  for pid in "$@"; do
    for child in $(pgrep -P "$pid" 2>/dev/null); do echo "$child"; descendants "$child"; done
  done
}
terminate() {  # terminate PID...: SIGTERM to each, up to 6 s for each to end, then SIGKILL
  local pid
  for pid in "$@"; do kill -TERM "$pid" 2>/dev/null || true; done
  for pid in "$@"; do
    for _ in $(seq 60); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -KILL "$pid" 2>/dev/null || true
  done
}
# wait_any: until a process of PIDS has ended; ENDED is its pid, the status its exit status.
# `wait -n PIDS` would miss one that ended before it was called (bash has already reaped it:
# "no such job") and wait for the next, for ever when the others run on.
wait_any() {
  local pid
  ENDED=""
  while [[ -z "$ENDED" ]]; do
    for pid in "${PIDS[@]}"; do
      kill -0 "$pid" 2>/dev/null || { ENDED="$pid"; break; }
    done
    [[ -n "$ENDED" ]] || sleep 0.2
  done
  wait "$ENDED"
}
stop_all() {
  trap - EXIT
  trap 'echo "$(basename "$0"): already stopping (a process still running after 6 s is killed)" >&2' INT TERM
  ((STOPPING)) && return
  STOPPING=1
  local below
  below="$(descendants "${PIDS[@]}")"
  terminate "${PIDS[@]}"
  # shellcheck disable=SC2086  # one pid per word
  terminate $below
  if declare -F on_stopped >/dev/null; then on_stopped; fi
}
