#!/usr/bin/env python3
"""Policy inference cost per call on one thread (onnxruntime intra/inter-op threads = 1):
the bare session.run, the runner (normalise + run + checks), and the whole tilt law tick
(PID + observation history + inference + scaling), on recorded observations, and a cycle of
the controller manager (mock arm, paced at 500 Hz) with the generic policy controller active. Prints
median / p99 / max in us and the load average (the p99 of a busy machine is scheduling).

    python benchmarks/policy_inference_bench.py [--calls 20000] [--model policies/residual_tilt.onnx]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "controller_manager_py"))  # its own package folder

from ball_balance.control.references import RefSample  # noqa: E402
from ball_balance.policy.observation import AXES, flat_names, layout  # noqa: E402
from ball_balance.policy.params import DEFAULT_MODEL, model_path  # noqa: E402
from ball_balance.policy.tilt_law import ACTION_KIND, PolicyTiltLaw  # noqa: E402

MANAGER_HZ = 500


def timed(fn, inputs, calls):
    out = np.empty(calls)
    n = len(inputs)
    for i in range(calls):
        x = inputs[i % n]
        t0 = time.perf_counter()
        fn(x)
        out[i] = time.perf_counter() - t0
    return out * 1e6


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--calls", type=int, default=20000)
    parser.add_argument("--model", default=DEFAULT_MODEL)
    args = parser.parse_args(argv)
    from ball_balance.control.pid import PidGains
    from controller_manager_py.controllers.policy_model import PolicyRunner

    path = model_path(args.model)
    runner = PolicyRunner.load(path, observation_names=flat_names(), action_kind=ACTION_KIND, action_count=2)
    check = path.with_suffix(".check.npz")
    if not check.exists():   # an installed model without its recorded observations: the source tree's
        check = ROOT / "config" / "policies" / check.name
    recorded = np.load(check)["observations"]
    z = ((recorded - runner.mean) * runner.inv_std).astype(np.float32)
    feeds = [{runner.input_name: z[i:i + 1]} for i in range(len(z))]
    law = PolicyTiltLaw(runner, PidGains(), 0.6 * 9.81, blend_s=0.0)
    rng = np.random.default_rng(0)
    states = [(rng.normal(0, 0.02, 2), rng.normal(0, 0.05, 2)) for _ in range(256)]
    ref = RefSample(np.zeros(2), np.zeros(2), np.zeros(2))
    cases = [
        ("onnxruntime session.run", lambda f: runner.session.run(None, f), feeds),
        ("PolicyRunner.infer (normalise + run + checks)", runner.infer, list(recorded)),
        ("tilt law tick (PID, history, infer, fade, scale)",
         lambda s: law.step(s[0], s[1], ref, 0.02, 0.03), states),
    ]
    for _, fn, inputs in cases:   # warm-up
        timed(fn, inputs, 500)
    print(f"model {path.name} ({path.stat().st_size} bytes), {args.calls} calls per row, one thread, "
          f"load average {os.getloadavg()[0]:.1f}")
    print(f"{'what':50} {'median us':>10} {'p99 us':>8} {'max us':>8}")
    for name, fn, inputs in cases:
        t = timed(fn, inputs, args.calls)
        print(f"{name:50} {np.median(t):10.1f} {np.percentile(t, 99):8.1f} {t.max():8.0f}")
    cm, ctrl = manager_with_policy(str(path))
    t = paced_cycles(cm, min(args.calls, 5 * MANAGER_HZ))
    print(f"{'manager cycle, 500 Hz paced, onnx_policy_controller':50} {np.median(t):10.1f} "
          f"{np.percentile(t, 99):8.1f} {t.max():8.0f}")
    print(f"onnx_policy_controller: {ctrl.inferences} inferences, {ctrl.missed_inferences} missed, "
          f"{ctrl.refused_observations} refused, inference "
          f"time mean {ctrl.inference_stats.average:.1f} us (worker thread)")
    ctrl.on_deactivate(None)
    return 0


def paced_cycles(cm, cycles: int) -> np.ndarray:
    """cm.cycle() every 1/MANAGER_HZ of wall time (as the loop does); each cycle's own time in us."""
    period = 1.0 / MANAGER_HZ
    out = np.empty(cycles)
    start = time.perf_counter()
    for i in range(cycles):
        deadline = start + (i + 1) * period
        while time.perf_counter() < deadline:
            time.sleep(max(0.0, deadline - time.perf_counter() - 0.0002))
        t0 = time.perf_counter()
        cm.cycle((i + 1) * period, period)
        out[i] = time.perf_counter() - t0
    return out * 1e6


def manager_with_policy(model: str):
    """The mock UR arm in a synthetic-time controller manager with the generic policy controller
    running the ball model (its inputs fed once; two joints stand in for the tilt pair)."""
    from controller_manager_py.manager.controller_manager import ControllerManager

    cm = ControllerManager(MANAGER_HZ)
    cm.load_robot_description((ROOT / "config" / "mock_ur.urdf").read_text())
    # every field of the ball's layout is a named input, but the tilts, which the controller
    # takes from its own commands; fed once with these values
    values = {"error_m": 0.01, "vel_error_m_s": 0.0, "ff_tilt_rad": 0.0, "pid_tilt_rad": 0.02, "age_s": 0.03,
              "gain_ratio": 1.0}
    fields = [name for name, _, _ in layout() if name != "tilt_rad"]
    inputs = [f"{a}.{name}" for a in AXES for name in fields]
    cm.load_controller("policy", "controller_manager_py.controllers.onnx_policy:OnnxPolicyController", {
        "model_path": model, "inputs": inputs, "observation_sources": ["x.tilt_rad=command.0", "y.tilt_rad=command.1"],
        "command_interfaces": ["shoulder_pan_joint/position", "wrist_3_joint/position"],
        "base_inputs": ["x.pid_tilt_rad", "y.pid_tilt_rad"],
        "state_interfaces": ["shoulder_pan_joint/position", "wrist_3_joint/position"]})
    cm.configure_controller("policy")
    cm.switch_controller(["policy"], [], 2)
    ctrl = cm.controllers["policy"].c
    ctrl.set_inputs([values[name] for _ in AXES for name in fields])
    return cm, ctrl


if __name__ == "__main__":
    sys.exit(main())
