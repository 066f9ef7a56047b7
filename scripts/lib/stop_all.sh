# Sourced by the scripts that compose a graph. They start each node in the background,
# append its pid to PIDS, and `trap stop_all INT TERM EXIT`. stop_all sends SIGTERM to every
# one (background jobs of a script ignore SIGINT; every node shuts down cleanly on SIGTERM),
# waits up to 6 s for each, SIGKILLs what is left, then runs the script's `on_stopped` if
# it defines one. A second Ctrl-C while it stops does not cut the stop short (the nodes
# ignore further signals while they shut down, ball_balance/ros/node_main.py): it is
# answered with one line, and whatever has not stopped 6 s after the first is killed.
PIDS=()
STOPPING=0
stop_all() {
  trap - EXIT
  trap 'echo "$(basename "$0"): already stopping (a process still running after 6 s is killed)" >&2' INT TERM
  ((STOPPING)) && return
  STOPPING=1
  local pid
  for pid in "${PIDS[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  for pid in "${PIDS[@]}"; do
    for _ in $(seq 60); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -KILL "$pid" 2>/dev/null || true
  done
  if declare -F on_stopped >/dev/null; then on_stopped; fi
}
