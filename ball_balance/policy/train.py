"""Train the residual balancing policy and export it as ONNX (CPU, reproducible from a seed).

    pip install -r requirements/train.txt          # torch + onnx, training only
    python -m ball_balance.policy.train --seed 0   # writes config/policies/residual_tilt.onnx

Method: imitation of a teacher with dataset aggregation (DAgger), the network's correction
added to the PID. The teacher (--teacher mpc_far, default) is the MPC as the mpc node runs it,
on the running controller's own estimate, wherever the ball is more than --teacher-far-mm off
the reference on an axis (all of it from twice that), and the PID itself nearer: the PID's one
weakness against the MPC is the way back from a push, and a label that is a function of what
the controller sees can be learned (a teacher on the true state labels what no observation
explains). The correction applies only beyond --correction-onset-mm from the reference (all
of it beyond twice it), in training and at run time, so where the PID is good the policy is
the PID. On a weak plant (the plant estimate's gain below --low-gain-onset of the tuned one)
the MPC's label and the correction apply near the reference too: there the PID, which never
scales its feedback up, is slow everywhere. Other teachers (--teacher): the PID itself on the
true state predicted exactly over the episode's latency with the true gain and bias (pid: the
correction is zero where the running PID's estimates are right), a stiffer PD law or the MPC
on the true state, and the PID on the truth near plus the MPC far (pid_mpc).

The student sees only what the running controller sees (the observation of
ball_balance/policy/observation.py, with the plant estimate's gain, which the MPC's tilt
scales with). Iteration 0 rolls out the PID alone (--first-rollout; the teacher's own
episodes teach the network to copy its last tilt, which it sees); every later iteration rolls
out the student itself and labels the states it visits with the teacher's tilt, so the
student learns to recover from its own mistakes. Samples can be weighted per episode
(--weight-power). Each iteration ends with an evaluation on held-out episodes, one bucket per
kind of benchmark domain, beside the PID alone; the exported iteration is the one nowhere (or
least) worse than the PID (a drop the PID does not have outweighs everything), then the gain
on its correction that does best there.
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

from ball_balance.policy.env import BASE_PID_KEYS, CONTROL_DT_S, TEACHERS, TRACKER_FILTER_KEYS, DomainRanges, PlateBatch
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


def rollout(env: PlateBatch, act, collect: bool, rng, every: int = 2, weight_power: float = 0.0,
            weight_floor: float = 0.01, push_label_frames: int = 0):
    """One batch of episodes; act(obs, env) -> tilt (teacher) or action. Returns (obs, label)
    rows; the label's second column is the row's loss weight: 1 / (RMS label of its episode's
    axis, at least weight_floor) ** weight_power, mean 1 (0: all 1), so that episodes where the
    PID needs little correction are not drowned by those that need much. Ticks between a push
    and push_label_frames camera frames after it (PlateBatch.push_visible) give no rows."""
    obs = env.reset()
    xs, ys, ids = [], [], []
    while not env.finished:
        if collect:
            label = env.residual_label(env.teacher_tilt()) if env.tick % every == 0 else None
        kind, value = act(obs, env)
        if collect and label is not None:
            keep = env.engaged & env.alive & env.push_visible(push_label_frames)
            xs.append(obs[keep].reshape(-1, axis_size()))
            ys.append(label[keep].reshape(-1))
            ids.append((2 * np.flatnonzero(keep)[:, None] + np.arange(2)).reshape(-1))
        obs = env.step(tilt=value) if kind == "tilt" else env.step(action=value)
    if not collect:
        return None, None
    y, ids = np.concatenate(ys), np.concatenate(ids)
    weight = np.ones_like(y)
    if weight_power > 0.0:
        rms = np.sqrt(np.bincount(ids, y * y, 2 * env.b) / np.maximum(np.bincount(ids, None, 2 * env.b), 1))
        weight = np.maximum(rms, weight_floor)[ids] ** -weight_power
        weight /= weight.mean()
    return np.concatenate(xs), np.stack([y, weight], 1)


def evaluate(act, seed: int, batch: int, ranges: DomainRanges, **env_args):
    env = PlateBatch(batch, seed, ranges, **env_args)
    rollout(env, act, False, None)
    r = env.rmse_steady_m()
    return {"drops": int((~env.alive).sum()), "rmse_mean_mm": float(np.nanmean(r) * 1e3),
            "rmse_median_mm": float(np.nanmedian(r) * 1e3), "rmse_p90_mm": float(np.nanpercentile(r, 90) * 1e3)}


def buckets(ranges: DomainRanges) -> dict:
    """Held-out evaluation buckets, one per kind of benchmark domain (sim/config.py DOMAINS):
    the exported iteration must not be worse than the PID alone in any of them."""
    calm = dict(latency_s=(0.0, 0.02), detection_noise_m=(0.0, 0.0005), frame_drop_prob=(0.0, 0.02),
                push_prob_per_s=0.0)
    replace = dataclasses.replace
    return {
        "nominal": replace(ranges, gravity_scale=(0.95, 1.05), solid_ball_prob=0.0, **calm),
        "gravity_ball": replace(ranges, gravity_scale=(0.45, 1.6), **calm),
        "noise": replace(ranges, **{**calm, "detection_noise_m": (0.002, 0.005)}),
        "latency": replace(ranges, **{**calm, "latency_s": (0.03, 0.21)}),
        "pushes": replace(ranges, **{**calm, "push_prob_per_s": 0.25, "push_speed_m_s": (0.1, 0.2)}),
        "wide": ranges,
    }


def versus_pid(result: dict, pid: dict) -> dict:
    """Per bucket: RMSE after 5 s over the PID's (both over the episodes neither dropped is not
    available here, so over each one's survivors) and the drops beyond the PID's."""
    out = {}
    for name, r in result.items():
        out[name] = {"ratio": r["rmse_mean_mm"] / max(pid[name]["rmse_mean_mm"], 1e-9),
                     "extra_drops": max(0, r["drops"] - pid[name]["drops"]), "drops": r["drops"]}
    return out


def selection_score(vs: dict) -> float:
    """Lower is better: a drop the PID alone does not have outweighs any RMSE; then the worst
    bucket against the PID (at or below 1 = nowhere worse than the PID), then the mean ratio."""
    worst = max(v["ratio"] for v in vs.values())
    mean = float(np.mean([v["ratio"] for v in vs.values()]))
    drops = sum(v["extra_drops"] for v in vs.values())
    return 100.0 * drops + max(worst, 1.0) + 0.1 * mean


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
    parser.add_argument("--epochs", type=int, default=6, help="passes over the aggregated data per iteration")
    parser.add_argument("--hidden", type=int, default=128,
                        help="width of the two hidden layers (128: 64 fits the MPC's far-off correction markedly "
                        "worse)")
    parser.add_argument("--action-scale", type=float, default=0.1, help="largest correction [rad]")
    parser.add_argument("--eval-batch", type=int, default=256)
    parser.add_argument("--max-rows", type=int, default=3_000_000, help="keep at most this many samples")
    parser.add_argument("--loss", choices=("mse", "huber"), default="mse",
                        help="huber: squared below 0.05 of the action range, linear above (the labels of states "
                        "the student cannot tell apart, e.g. just after a push, weigh less)")
    parser.add_argument("--final-lr", type=float, default=1e-4,
                        help="learning rate of the last iteration (geometric from 1e-3)")
    parser.add_argument("--teacher", choices=TEACHERS, default="mpc_far",
                        help="the label: pid = the PID itself on the true state (exact latency prediction, true "
                        "gain and bias: the correction is zero where the PID's estimates are right); pd = a "
                        "stiffer PD law on the true state; mpc = the MPC (config/mpc.yaml) on the true state, "
                        "its unconstrained first move clipped to its limits; pid_mpc = pid within --teacher-far-mm "
                        "of the reference (per axis), the MPC on the running controller's own estimate beyond twice "
                        "it, blended between (after a push the MPC brings the ball back sooner, and its label is "
                        "what the controller can see); mpc_far = as pid_mpc with the running PID itself near the "
                        "reference (no correction there)")
    parser.add_argument("--teacher-far-mm", type=float, default=8.0,
                        help="pid_mpc and mpc_far: the error per axis up to which the label is the near law's (the "
                        "MPC's from twice it)")
    parser.add_argument("--residual-penalty", type=float, default=0.0,
                        help="weight of the mean absolute action (in [-1, 1] units) added to the loss: a "
                        "correction whose expected label is below half of it is learned as zero. For the pid "
                        "teacher 0.05 (corrections only where they pay); with mpc_far and its onset none: the "
                        "onset already keeps the correction out of where the PID is good, and 0.05 shrinks the "
                        "far-off labels toward zero")
    parser.add_argument("--push-prob-per-s", type=float, default=None,
                        help="random pushes per second in the training episodes (default: DomainRanges')")
    parser.add_argument("--push-label-frames", type=int, default=2,
                        help="learn nothing from the ticks between a random push and this many camera frames after "
                        "it reaching the controller: the teacher, on the true state, answers the push at once, a "
                        "label no observation explains (0: learn from every tick)")
    parser.add_argument("--first-rollout", choices=("pid", "teacher"), default="pid",
                        help="who drives iteration 0's episodes: pid = the PID alone (no correction), teacher = "
                        "the teacher. The observation holds the tilts commanded before, so on the teacher's own "
                        "episodes the label is nearly the last tilt minus the PID's: a network fitted to them "
                        "copies its own last output and chatters")
    parser.add_argument("--weight-power", type=float, default=0.0,
                        help="weigh each sample by 1 / (RMS label of its episode's axis) ** this (0: equal weights)")
    parser.add_argument("--weight-floor-rad", type=float, default=0.001,
                        help="the RMS label below which episodes weigh no more [rad]")
    parser.add_argument("--bucket-batch", type=int, default=64,
                        help="held-out episodes per evaluation bucket (buckets(); 0: select on --eval-batch "
                        "wide-range episodes by mean RMSE)")
    parser.add_argument("--output-gains", default="1,0.7,0.5,0.35,0.25,0.15,0.1,0.05",
                        help="comma-separated gains on the chosen iteration's correction, each evaluated on the "
                        "buckets beside the PID; the best is exported (as the action scale times it): the "
                        "network's imitation error costs most where the PID is already good")
    parser.add_argument("--correction-fade-mm", type=float, default=0.0,
                        help="the correction applies in full within this distance of the reference and fades out "
                        "to none at twice it (observation.correction_weight; recorded in the model, the runtime "
                        "applies the same; 0: everywhere). Far off, the ball is coming back from a push, where "
                        "the held-out pushes episodes show the correction costing at every output gain. Off by "
                        "default: in the MuJoCo benchmark a fade does not beat the unfaded model")
    parser.add_argument("--correction-onset-mm", type=float, default=8.0,
                        help="no correction within this distance of the reference, all of it beyond twice it "
                        "(observation.correction_weight; recorded in the model, the runtime applies the same; 0: "
                        "everywhere). With the mpc_far teacher the label is zero near the reference: the onset "
                        "keeps the network's imitation error out of where the PID is already good")
    parser.add_argument("--low-gain-onset", type=float, default=0.8,
                        help="with the onset: the correction (and the MPC's label) near the reference too where the "
                        "plant estimate's gain is below this ratio of the tuned one, all of it below its square "
                        "(observation.low_gain_share; recorded in the model, the runtime applies the same; 0: "
                        "not). On a weak plant the MPC beats the PID everywhere, not only off the reference")
    parser.add_argument("--save-iterations", default="", help="also write every iteration's model into this folder")
    parser.add_argument("--base-pid", nargs="*", default=[], metavar="NAME=VALUE",
                        help="PID parameters over config/policy.yaml's for the training (recorded in the model; "
                        "the node refuses it unless its configuration sets the same)")
    parser.add_argument("--out", default=str(DEFAULT_OUT))
    args = parser.parse_args(argv)
    torch = _torch()
    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    rng = np.random.default_rng(args.seed)
    ranges = DomainRanges()
    if args.push_prob_per_s is not None:
        ranges = dataclasses.replace(ranges, push_prob_per_s=args.push_prob_per_s)
    t_start = time.monotonic()
    eval_seed = 10_000_000 + args.seed

    def pid_only(obs, env):
        return "action", None

    def teacher(obs, env):
        return "tilt", env.teacher_tilt()

    pid_overrides = tuple((name, yaml.safe_load(value)) for name, value in
                          (item.split("=", 1) for item in args.base_pid))
    env_args = dict(action_scale_rad=args.action_scale, teacher=args.teacher, pid_overrides=pid_overrides,
                    correction_fade_m=args.correction_fade_mm * 1e-3, teacher_far_m=args.teacher_far_mm * 1e-3,
                    correction_onset_m=args.correction_onset_mm * 1e-3, low_gain_onset=args.low_gain_onset)
    bucket_ranges = buckets(ranges) if args.bucket_batch > 0 else {}

    def evaluate_all(act):
        if not bucket_ranges:
            return {"wide": evaluate(act, eval_seed, args.eval_batch, ranges, **env_args)}
        return {name: evaluate(act, eval_seed + 17 * i, args.bucket_batch, r, **env_args)
                for i, (name, r) in enumerate(bucket_ranges.items())}

    pid_eval = evaluate_all(pid_only)
    print(f"PID alone on the evaluation episodes: {json.dumps(pid_eval)}", flush=True)
    env = PlateBatch(args.batch, args.seed * 1000, ranges, **env_args)
    collect = dict(weight_power=args.weight_power, weight_floor=args.weight_floor_rad / args.action_scale,
                   push_label_frames=args.push_label_frames)
    X, Y = rollout(env, teacher if args.first_rollout == "teacher" else pid_only, True, rng, **collect)
    flat = X.reshape(-1, axis_size())
    mean_axis, std_axis = flat.mean(0), flat.std(0) + 1e-6
    mean, std = np.tile(mean_axis, 2), np.tile(std_axis, 2)
    net = make_net(torch, args.hidden)
    student = Student(torch, net, mean, std)
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    lr_factor = (args.final_lr / 1e-3) ** (1.0 / max(args.iterations, 1))

    def loss_of(pred, target_weight):
        target, weight = target_weight[:, :1], target_weight[:, 1:]
        penalty = args.residual_penalty * torch.mean(torch.abs(pred)) if args.residual_penalty > 0 else 0.0
        if args.loss == "huber":
            return torch.mean(weight * torch.nn.functional.smooth_l1_loss(pred, target, beta=0.05, reduction="none")) \
                + penalty
        return torch.mean(weight * (pred - target) ** 2) + penalty
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

    method = {"pid": "DAgger imitation of the PID itself on the true state (exact latency prediction, true gain and "
                     "bias), residual on the PID",
              "mpc": "DAgger imitation of the MPC's unconstrained first move on the true state (exact latency "
                     "prediction, true gain and bias), residual on the PID",
              "pid_mpc": "DAgger imitation of the PID on the true state (exact latency prediction, true gain and "
                         "bias) near the reference and of the MPC on the running estimate far from it, residual on "
                         "the PID",
              "mpc_far": "DAgger imitation of the MPC on the running estimate far from the reference and of the "
                         "PID itself near it, residual on the PID",
              "pd": "DAgger imitation of a privileged PD teacher, residual on the PID"}[args.teacher]

    def export(path: Path, network, evaluation: dict, evaluated: list, elapsed_s: float, gain: float = 1.0,
               gains_evaluated=()) -> None:
        training = {"method": method, "output_gain": gain, "output_gains_evaluated": list(gains_evaluated),
                    "teacher": args.teacher, "residual_penalty": args.residual_penalty,
                    "teacher_far_m": args.teacher_far_mm * 1e-3,
                    "first_rollout": args.first_rollout, "push_label_frames": args.push_label_frames,
                    "correction_fade_error_m": args.correction_fade_mm * 1e-3,
                    "correction_onset_error_m": args.correction_onset_mm * 1e-3,
                    "correction_low_gain_onset": args.low_gain_onset,
                    "weight_power": args.weight_power,
                    "weight_floor_rad": args.weight_floor_rad,
                    "seed": args.seed, "commit": commit_id(), "iterations": args.iterations, "batch": args.batch,
                    "epochs": args.epochs, "loss": args.loss, "final_lr": args.final_lr, "hidden": args.hidden,
                    "samples": int(len(X)),
                    "wall_time_s": round(elapsed_s, 1), "torch": torch.__version__, "domains": ranges.as_dict(),
                    "evaluation_buckets": {k: v.as_dict() for k, v in bucket_ranges.items()},
                    "pid_evaluation": pid_eval, "evaluation": evaluation, "iterations_evaluated": evaluated,
                    "base_pid": {k: env.pid_values[k] for k in BASE_PID_KEYS},
                    "tracker_filter": {k: getattr(env.tracker_cfg, k) for k in TRACKER_FILTER_KEYS
                                       if hasattr(env.tracker_cfg, k)},
                    "command": "python -m ball_balance.policy.train " + " ".join(
                        sys.argv[1:] if argv is None else argv)}
        weights = [(m.weight.detach().numpy(), m.bias.detach().numpy()) for m in network if hasattr(m, "weight")]
        metadata = make_metadata(
            observation=ObservationSpec(names=flat_names(), mean=mean.tolist(), std=std.tolist(),
                                        layout=[[n, s, u] for n, s, u in layout()], history=HISTORY,
                                        axes=["x", "y"]),
            action=ActionSpec(names=["x.tilt_correction", "y.tilt_correction"], kind="residual_tilt",
                              unit="rad", scale=[args.action_scale * gain] * 2, low=[-0.15, -0.15], high=[0.15, 0.15]),
            rate_hz=1.0 / CONTROL_DT_S, training=training)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_mlp_onnx(path, weights, axis_size(), 2, metadata)

    for it in range(args.iterations + 1):
        if it > 0:
            for group in opt.param_groups:
                group["lr"] *= lr_factor
            env = PlateBatch(args.batch, args.seed * 1000 + it, ranges, **env_args)
            Xi, Yi = rollout(env, act_student, True, rng, **collect)
            X, Y = np.concatenate([X, Xi]), np.concatenate([Y, Yi])
            if len(X) > args.max_rows:
                keep = rng.choice(len(X), args.max_rows, replace=False)
                X, Y = X[keep], Y[keep]
        loss = fit(X, Y, args.epochs)
        per_bucket = evaluate_all(act_student)
        if bucket_ranges:
            vs = versus_pid(per_bucket, pid_eval)
            score = selection_score(vs)
            result = {"score": round(score, 4), "buckets": {k: {**per_bucket[k], "ratio_to_pid": round(v["ratio"], 3)}
                                                            for k, v in vs.items()}}
        else:
            result = dict(per_bucket["wide"])
            score = result["rmse_mean_mm"] + 100.0 * result["drops"]   # a drop outweighs any RMSE gain
        result.update(iteration=it, samples=len(X), loss=loss, elapsed_s=round(time.monotonic() - t_start, 1))
        history.append(result)
        print(json.dumps(result), flush=True)
        if args.save_iterations:
            export(Path(args.save_iterations) / f"iteration_{it}.onnx", net, result, history,
                   time.monotonic() - t_start)
        if best is None or score < best[0]:
            best = (score, it, copy.deepcopy(net.state_dict()), result)
    # ship the iteration that did best on the held-out episodes
    net.load_state_dict(best[2])
    print(f"iteration {best[1]} chosen: {json.dumps(best[3])}", flush=True)
    # and the gain on its correction that does best there (1 = as trained)
    gain, gains_evaluated = 1.0, [{"gain": 1.0, "score": best[0], "evaluation": best[3]}]
    if bucket_ranges:
        for g in (float(x) for x in args.output_gains.split(",") if x.strip()):
            if g == 1.0:
                continue
            per_bucket = evaluate_all(lambda obs, env, g=g: ("action", g * student(obs)))
            vs = versus_pid(per_bucket, pid_eval)
            score = selection_score(vs)
            result = {"score": round(score, 4), "buckets": {k: {**per_bucket[k], "ratio_to_pid": round(v["ratio"], 3)}
                                                            for k, v in vs.items()}}
            gains_evaluated.append({"gain": g, "score": score, "evaluation": result})
            print(json.dumps({"gain": g, **result}), flush=True)
            if score < best[0]:
                best, gain = (score, best[1], best[2], {**result, "iteration": best[1]}), g
    print(f"exporting iteration {best[1]} with gain {gain} (action scale {args.action_scale * gain:g} rad)",
          flush=True)

    # recorded observations for the export check: the student's own states
    env = PlateBatch(8, eval_seed + 1, ranges, **env_args)
    obs = env.reset()
    recorded = []
    while not env.finished:
        if env.tick % 25 == 0:
            recorded.append(obs.copy())
        obs = env.step(action=student(obs))
    recorded = np.concatenate(recorded)
    actions = student(recorded)
    elapsed = time.monotonic() - t_start
    out = Path(args.out)
    export(out, net, best[3], history, elapsed, gain, gains_evaluated)
    np.savez_compressed(out.with_suffix(".check.npz"), observations=recorded, actions=actions)
    print(f"wrote {out} ({out.stat().st_size} bytes) and {out.with_suffix('.check.npz').name}; "
          f"training took {elapsed:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
