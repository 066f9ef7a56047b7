#!/usr/bin/env bash
# Simulated UR arm + tracker + the learned policy (ball_balance_policy: the PID plus the ONNX
# policy's correction, config/policy.yaml) + visualizer (see scripts/sim_balance.sh for every
# option). Ctrl-C stops everything.
#
#   scripts/sim_policy.sh
#   scripts/sim_policy.sh --reference circle --radius 0.1 --period 10 --domain full_dr
#   scripts/sim_policy.sh --param policy_model:=/path/to/other.onnx
for arg; do  # --help: sim_balance.sh's, under a line naming this script
  case "$arg" in -h|--help) echo "sim_policy.sh runs scripts/sim_balance.sh --controller policy and takes its options:"; echo; break ;; esac
done
exec "$(dirname "${BASH_SOURCE[0]}")/sim_balance.sh" --controller policy "$@"
