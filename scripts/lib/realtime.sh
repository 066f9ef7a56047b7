# Sourced by the graph scripts: whether the control chain gets SCHED_FIFO on this machine.
#
# A real-time thread that has work runs until it is done, ahead of everything normally
# scheduled. That helps the control chain only while each real-time thread can have a CPU of
# its own and one CPU is left for the rest (the software renderer, the monitor, the scripts'
# CLI calls): on fewer CPUs the chain starved them. In simulation, lock-step pacing keeps the
# outcome whatever the scheduling, so there the only cost of normal scheduling is speed.
#
#   realtime_for N [--later]
#                    sets REALTIME=1 when N real-time threads fit this machine's CPUs
#                    (nproc: the CPUs this process may run on), else REALTIME=0, and says
#                    which and why on stderr (with --later: in REALTIME_NOTE, for the script
#                    to print once its checks passed). BALL_BALANCE_REALTIME=on|off overrides it.
realtime_for() {
  local needed="$1" cpus
  cpus="$(nproc)"
  case "${BALL_BALANCE_REALTIME:-auto}" in
    on) REALTIME=1; REALTIME_NOTE="SCHED_FIFO for the control chain (BALL_BALANCE_REALTIME=on)" ;;
    off) REALTIME=0; REALTIME_NOTE="normal scheduling (BALL_BALANCE_REALTIME=off)" ;;
    auto)
      if ((cpus > needed)); then
        REALTIME=1
        REALTIME_NOTE="SCHED_FIFO for the control chain ($needed real-time threads, $cpus CPUs)"
      else
        REALTIME=0
        REALTIME_NOTE="normal scheduling: $cpus CPUs are too few for $needed real-time threads and the rest"
        REALTIME_NOTE+=" (BALL_BALANCE_REALTIME=on forces it)"
      fi ;;
    *) echo "$(basename "$0"): BALL_BALANCE_REALTIME must be on, off or auto" >&2; exit 2 ;;
  esac
  REALTIME_NOTE="$(basename "$0"): $REALTIME_NOTE"
  [[ "${2:-}" == --later ]] || echo "$REALTIME_NOTE" >&2
  export BALL_BALANCE_REALTIME
  ((REALTIME)) && BALL_BALANCE_REALTIME=on || BALL_BALANCE_REALTIME=off   # the scripts it starts agree
}
