#!/usr/bin/env bash
# Simulated UR arm + tracker + PID balance controller + visualizer (see scripts/sim_balance.sh
# for every option). Ctrl-C stops everything.
#
#   scripts/sim_pid.sh
#   scripts/sim_pid.sh --reference circle --radius 0.1 --period 10
exec "$(dirname "${BASH_SOURCE[0]}")/sim_balance.sh" --controller pid "$@"
