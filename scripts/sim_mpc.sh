#!/usr/bin/env bash
# Simulated UR arm (scaled_joint_trajectory_controller active) + tracker + MPC balance
# controller + visualizer (see scripts/sim_balance.sh for every option). Ctrl-C stops everything.
#
#   scripts/sim_mpc.sh
#   scripts/sim_mpc.sh --reference figure_eight --radius 0.1 --period 12
for arg; do  # --help: sim_balance.sh's, under a line naming this script
  case "$arg" in -h|--help) echo "sim_mpc.sh runs scripts/sim_balance.sh --controller mpc and takes its options:"; echo; break ;; esac
done
exec "$(dirname "${BASH_SOURCE[0]}")/sim_balance.sh" --controller mpc "$@"
