"""Train the residual balancing policy and export it as ONNX (CPU, reproducible from a seed).

    pip install -r requirements/train.txt          # torch + onnx, training only
    python -m ball_balance.policy.train --seed 0   # writes config/policies/residual_tilt.onnx

Method: imitation of a privileged teacher with dataset aggregation (DAgger). In the
vectorised plant (ball_balance/policy/env.py) every episode knows its own latency, servo lag,
gravity, ball type and plate bias; a PD law on the true state predicted exactly over that
latency is the teacher. The student sees only what the running controller sees (the
observation of ball_balance/policy/observation.py) and learns the correction to add to the
PID that brings its tilt to the teacher's. Iteration 0 rolls out the teacher; every later
iteration rolls out the student itself and labels the states it visits with the teacher's
tilt, so the student learns to recover from its own mistakes. Each iteration ends with an
evaluation on held-out episodes beside the PID alone.
"""
from __future__ import annotations

import argparse
import copy
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from ball_balance.policy.env import BASE_PID_KEYS, CONTROL_DT_S, TRACKER_FILTER_KEYS, DomainRanges, PlateBatch
from ball_balance.policy.export import write_mlp_onnx
from ball_balance.policy.observation import HISTORY, axis_size, flat_names, layout
from controller_manager_py.controllers.policy_model import ActionSpec, ObservationSpec, make_metadata

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_OUT = ROOT / "config" / "policies" / "residual_tilt.onnx"


def _torch():
    try:
        import torch
    except ImportError:
        raise SystemExit("training needs torch: pip install -r requirements/train.txt") from None
    return torch


def make_net(torch, hidden: int):
    """The per-axis network; its output is the correction in [-1, 1]."""
    nn = torch.nn
    return nn.Sequential(nn.Linear(axis_size(), hidden), nn.Tanh(), nn.Linear(hidden, hidden), nn.Tanh(),
                         nn.Linear(hidden, 1), nn.Tanh())


class Student:
    """The network with the normalisation, on raw flat observations (batch, 2 * axis_size)."""

    def __init__(self, torch, net, mean: np.ndarray, std: np.ndarray):
        self.torch, self.net, self.mean, self.std = torch, net, mean, std

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        torch = self.torch
        z = (obs - self.mean) / self.std
        with torch.no_grad():
            out = self.net(torch.from_numpy(z.reshape(-1, axis_size()).astype(np.float32)))
        return out.numpy().reshape(obs.shape[0], 2)


def rollout(env: PlateBatch, act, collect: bool, rng, every: int = 2):
    """One batch of episodes; act(obs, env) -> tilt (teacher) or action. Returns (obs, label) rows."""
    obs = env.reset()
    xs, ys = [], []
    while not env.finished:
        if collect:
            label = env.residual_label(env.teacher_tilt()) if env.tick % every == 0 else None
        kind, value = act(obs, env)
        if collect and label is not None:
            keep = env.engaged & env.alive
            xs.append(obs[keep].reshape(-1, axis_size()))
            ys.append(label[keep].reshape(-1, 1))
        obs = env.step(tilt=value) if kind == "tilt" else env.step(action=value)
    if not collect:
        return None, None
    return np.concatenate(xs), np.concatenate(ys)


def evaluate(act, seed: int, batch: int, ranges: DomainRanges):
    env = PlateBatch(batch, seed, ranges)
    rollout(env, act, False, None)
    r = env.rmse_steady_m()
    return {"drops": int((~env.alive).sum()), "rmse_mean_mm": float(np.nanmean(r) * 1e3),
            "rmse_median_mm": float(np.nanmedian(r) * 1e3), "rmse_p90_mm": float(np.nanpercentile(r, 90) * 1e3)}


def commit_id() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=True)
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "ball_balance/policy"], cwd=ROOT,
                               capture_output=True, text=True).stdout.strip()
        return out.stdout.strip() + ("-dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--iterations", type=int, default=7, help="DAgger iterations (0 = teacher only)")
    parser.add_argument("--batch", type=int, default=384, help="episodes rolled out per iteration")
    parser.add_argument("--epochs", type=int, default=3, help="passes over the aggregated data per iteration")
    parser.add_argument("--hidden", type=int, default=64)
    parser.add_argument("--action-scale", type=float, default=0.1, help="largest correction [rad]")
    parser.add_argument("--eval-batch", type=int, default=256)
    parser.add_argument("--max-rows", type=int, default=3_000_000, help="keep at most this many samples")
    parser.add_argument("--loss", choices=("mse", "huber"), default="mse",
                        help="huber: squared below 0.05 of the action range, linear above (the labels of states "
                        "the student cannot tell apart, e.g. just after a push, weigh less)")
    parser.add_argument("--final-lr", type=float, default=1e-3,
                        help="learning rate of the last iteration (geometric from 1e-3)")
    parser.add_argument("--out", default=str(DEFAULT_OUT))
    args = parser.parse_args(argv)
    torch = _torch()
    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    rng = np.random.default_rng(args.seed)
    ranges = DomainRanges()
    t_start = time.monotonic()
    eval_seed = 10_000_000 + args.seed

    def pid_only(obs, env):
        return "action", None

    def teacher(obs, env):
        return "tilt", env.teacher_tilt()

    print(f"PID alone on the evaluation episodes: {evaluate(pid_only, eval_seed, args.eval_batch, ranges)}",
          flush=True)
    env = PlateBatch(args.batch, args.seed * 1000, ranges, action_scale_rad=args.action_scale)
    X, Y = rollout(env, teacher, True, rng)
    flat = X.reshape(-1, axis_size())
    mean_axis, std_axis = flat.mean(0), flat.std(0) + 1e-6
    mean, std = np.tile(mean_axis, 2), np.tile(std_axis, 2)
    net = make_net(torch, args.hidden)
    student = Student(torch, net, mean, std)
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    lr_factor = (args.final_lr / 1e-3) ** (1.0 / max(args.iterations, 1))

    def loss_of(pred, target):
        if args.loss == "huber":
            return torch.nn.functional.smooth_l1_loss(pred, target, beta=0.05)
        return torch.mean((pred - target) ** 2)
    history = []
    best = None

    def fit(X, Y, epochs):
        Xn = torch.from_numpy(((X - mean_axis) / std_axis).astype(np.float32))
        Yt = torch.from_numpy(Y.astype(np.float32))
        n = len(Xn)
        loss_sum = 0.0
        for _ in range(epochs):
            perm = torch.randperm(n)
            loss_sum, count = 0.0, 0
            for i in range(0, n, 4096):
                idx = perm[i:i + 4096]
                loss = loss_of(net(Xn[idx]), Yt[idx])
                opt.zero_grad()
                loss.backward()
                opt.step()
                loss_sum, count = loss_sum + loss.item(), count + 1
            loss_sum /= max(count, 1)
        return loss_sum

    def act_student(obs, env):
        return "action", student(obs)

    for it in range(args.iterations + 1):
        if it > 0:
            for group in opt.param_groups:
                group["lr"] *= lr_factor
            env = PlateBatch(args.batch, args.seed * 1000 + it, ranges, action_scale_rad=args.action_scale)
            Xi, Yi = rollout(env, act_student, True, rng)
            X, Y = np.concatenate([X, Xi]), np.concatenate([Y, Yi])
            if len(X) > args.max_rows:
                keep = rng.choice(len(X), args.max_rows, replace=False)
                X, Y = X[keep], Y[keep]
        loss = fit(X, Y, args.epochs)
        result = evaluate(act_student, eval_seed, args.eval_batch, ranges)
        result.update(iteration=it, samples=len(X), loss=loss, elapsed_s=round(time.monotonic() - t_start, 1))
        history.append(result)
        print(json.dumps(result), flush=True)
        score = result["rmse_mean_mm"] + 100.0 * result["drops"]   # a drop outweighs any RMSE gain
        if best is None or score < best[0]:
            best = (score, it, copy.deepcopy(net.state_dict()), result)
    # ship the iteration that did best on the held-out episodes
    net.load_state_dict(best[2])
    print(f"exporting iteration {best[1]}: {json.dumps(best[3])}", flush=True)

    # recorded observations for the export check: the student's own states
    env = PlateBatch(8, eval_seed + 1, ranges, action_scale_rad=args.action_scale)
    obs = env.reset()
    recorded = []
    while not env.finished:
        if env.tick % 25 == 0:
            recorded.append(obs.copy())
        obs = env.step(action=student(obs))
    recorded = np.concatenate(recorded)
    actions = student(recorded)
    elapsed = time.monotonic() - t_start
    training = {"method": "DAgger imitation of a privileged PD teacher, residual on the PID",
                "seed": args.seed, "commit": commit_id(), "iterations": args.iterations, "batch": args.batch,
                "epochs": args.epochs, "loss": args.loss, "final_lr": args.final_lr, "hidden": args.hidden,
                "samples": int(len(X)),
                "wall_time_s": round(elapsed, 1), "torch": torch.__version__, "domains": ranges.as_dict(),
                "evaluation": best[3], "iterations_evaluated": history,
                "base_pid": {k: env.pid_values[k] for k in BASE_PID_KEYS},
                "tracker_filter": {k: getattr(env.tracker_cfg, k) for k in TRACKER_FILTER_KEYS
                                   if hasattr(env.tracker_cfg, k)},
                "command": "python -m ball_balance.policy.train " + " ".join(
                    sys.argv[1:] if argv is None else argv)}
    weights = [(m.weight.detach().numpy(), m.bias.detach().numpy()) for m in net if hasattr(m, "weight")]
    metadata = make_metadata(
        observation=ObservationSpec(names=flat_names(), mean=mean.tolist(), std=std.tolist(),
                                         layout=[[n, s, u] for n, s, u in layout()], history=HISTORY,
                                         axes=["x", "y"]),
        action=ActionSpec(names=["x.tilt_correction", "y.tilt_correction"], kind="residual_tilt",
                               unit="rad", scale=[args.action_scale] * 2, low=[-0.15, -0.15], high=[0.15, 0.15]),
        rate_hz=1.0 / CONTROL_DT_S, training=training)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_mlp_onnx(out, weights, axis_size(), 2, metadata)
    np.savez_compressed(out.with_suffix(".check.npz"), observations=recorded, actions=actions)
    print(f"wrote {out} ({out.stat().st_size} bytes) and {out.with_suffix('.check.npz').name}; "
          f"training took {elapsed:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
