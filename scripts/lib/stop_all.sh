# Sourced by the scripts that compose a graph. They start each node in the background,
# append its pid to PIDS, and `trap stop_all INT TERM EXIT`. stop_all sends SIGTERM to every
# one (background jobs of a script ignore SIGINT; every node shuts down cleanly on SIGTERM),
# waits up to 6 s for each, SIGKILLs what is left, then runs the script's `on_stopped` if
# it defines one.
PIDS=()
stop_all() {
  trap - INT TERM EXIT
  local pid
  for pid in "${PIDS[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  for pid in "${PIDS[@]}"; do
    for _ in $(seq 60); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -KILL "$pid" 2>/dev/null || true
  done
  if declare -F on_stopped >/dev/null; then on_stopped; fi
}
