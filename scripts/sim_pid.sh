#!/usr/bin/env bash
# Simulated UR arm + tracker + PID balance controller + visualizer (see scripts/sim_balance.sh
# for every option). Ctrl-C stops everything.
#
#   scripts/sim_pid.sh
#   scripts/sim_pid.sh --reference circle --radius 0.1 --period 10
for arg; do  # --help: sim_balance.sh's, under a line naming this script
  case "$arg" in -h|--help) echo "sim_pid.sh runs scripts/sim_balance.sh --controller pid and takes its options:"; echo; break ;; esac
done
exec "$(dirname "${BASH_SOURCE[0]}")/sim_balance.sh" --controller pid "$@"
