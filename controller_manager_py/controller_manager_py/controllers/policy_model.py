"""Policy models for onnxruntime (no torch, no ROS): the metadata a model file carries, checked
on load, and a runner that normalises, infers, scales and clamps. Generic: nothing here
knows what the observations or actions mean.

The model maps a normalised observation vector (float32, [batch, n_obs]) to raw actions in
[-1, 1] ([batch, n_act]). Its ONNX `metadata_props` carry, as JSON strings:

    policy_format   "1"
    observation     {"names": [n_obs], "mean": [n_obs], "std": [n_obs], ...}: z = (obs - mean) / std
    action          {"names": [n_act], "kind", "unit", "scale": [n_act], "low": [n_act], "high": [n_act]}:
                    the command is action * scale (added to a base command for a kind "residual_*"),
                    then clamped to [low, high]
    rate_hz         the rate the policy was trained at (an observation history assumes it)
    training        how it was made: at least its seed and the commit it was trained from

`read_model` checks all of it; a missing or inconsistent field raises PolicyModelError with
one line naming the model and the field. `PolicyRunner.load` also refuses a model that does
not fit what the caller will feed it (observation names, action kind and count, rate).

    runner = PolicyRunner.load(path, observation_names=..., action_kind=..., rate_hz=...)
    action = runner.infer(obs)     # raw action per output, or None (non-finite input or output)
    command = runner.command(action, base)
"""
from __future__ import annotations

import json
import math
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import List, Optional, Sequence

import numpy as np

FORMAT = "1"
REQUIRED_KEYS = ("policy_format", "observation", "action", "rate_hz", "training")


class PolicyModelError(ValueError):
    """A policy model cannot be used (the message names the model and what is wrong)."""


@dataclass(frozen=True)
class ObservationSpec:
    names: List[str]
    mean: List[float]
    std: List[float]
    layout: list = field(default_factory=list)   # [name, size, unit] of one axis (informative)
    history: int = 0
    axes: List[str] = field(default_factory=list)

    @property
    def size(self) -> int:
        return len(self.names)


@dataclass(frozen=True)
class ActionSpec:
    names: List[str]
    kind: str            # "residual_tilt": added to the base controller's command; "absolute": the command
    unit: str
    scale: List[float]
    low: List[float]
    high: List[float]

    @property
    def size(self) -> int:
        return len(self.names)


@dataclass(frozen=True)
class PolicyMetadata:
    observation: ObservationSpec
    action: ActionSpec
    rate_hz: float
    training: dict

    def props(self) -> dict:
        """The metadata_props dict (all values strings)."""
        return {"policy_format": FORMAT, "observation": json.dumps(asdict(self.observation)),
                "action": json.dumps(asdict(self.action)), "rate_hz": repr(float(self.rate_hz)),
                "training": json.dumps(self.training)}


def make_metadata(observation: ObservationSpec, action: ActionSpec, rate_hz: float, training: dict) -> PolicyMetadata:
    md = PolicyMetadata(observation, action, rate_hz, training)
    check(md, "new model")
    return md


def parse(props: dict, where: str) -> PolicyMetadata:
    """PolicyMetadata from a model's metadata_props (PolicyModelError names what is wrong)."""
    missing = [k for k in REQUIRED_KEYS if k not in props]
    if missing:
        raise PolicyModelError(f"policy model {where}: metadata lacks {missing} (is it a policy exported with "
                               "policy_model.make_metadata?)")
    if props["policy_format"] != FORMAT:
        raise PolicyModelError(f"policy model {where}: policy_format {props['policy_format']!r}, this runtime "
                               f"reads {FORMAT!r}")
    try:
        obs, act = json.loads(props["observation"]), json.loads(props["action"])
        md = PolicyMetadata(ObservationSpec(**obs), ActionSpec(**act), float(props["rate_hz"]),
                            json.loads(props["training"]))
    except (TypeError, ValueError) as exc:
        raise PolicyModelError(f"policy model {where}: unreadable metadata ({exc})") from None
    check(md, where)
    return md


def check(md: PolicyMetadata, where: str) -> None:
    o, a = md.observation, md.action

    def bad(what):
        raise PolicyModelError(f"policy model {where}: {what}")

    if not o.names:
        bad("observation.names is empty")
    for name in ("mean", "std"):
        values = getattr(o, name)
        if len(values) != o.size or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
            bad(f"observation.{name} needs {o.size} finite numbers")
    if any(v <= 0 for v in o.std):
        bad("observation.std must be > 0")
    if not a.names:
        bad("action.names is empty")
    for name in ("scale", "low", "high"):
        values = getattr(a, name)
        if len(values) != a.size or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
            bad(f"action.{name} needs {a.size} finite numbers")
    if any(lo > hi for lo, hi in zip(a.low, a.high, strict=True)):
        bad("action.low must be <= action.high")
    if not (math.isfinite(md.rate_hz) and md.rate_hz > 0):
        bad(f"rate_hz {md.rate_hz} must be > 0")
    for key in ("seed", "commit"):
        if key not in md.training:
            bad(f"training.{key} missing")


def read_model(path, providers: Optional[list] = None):
    """(onnxruntime.InferenceSession, PolicyMetadata) of a policy model file, checked: the
    metadata, and the graph's input and output widths against it."""
    import onnxruntime as ort

    path = Path(path)
    if not path.is_file():
        raise PolicyModelError(f"policy model {path}: no such file")
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1     # a tiny MLP: threads cost more than they give
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    try:
        session = ort.InferenceSession(str(path), options, providers=providers or ["CPUExecutionProvider"])
    except Exception as exc:   # onnxruntime raises its own exception types
        raise PolicyModelError(f"policy model {path}: onnxruntime cannot load it ({str(exc).splitlines()[0]})") \
            from None
    md = parse(dict(session.get_modelmeta().custom_metadata_map), str(path))
    inputs, outputs = session.get_inputs(), session.get_outputs()
    if len(inputs) != 1 or len(outputs) != 1:
        raise PolicyModelError(f"policy model {path}: needs one input and one output, has {len(inputs)} and "
                               f"{len(outputs)}")
    width_in, width_out = inputs[0].shape[-1], outputs[0].shape[-1]
    if width_in != md.observation.size:
        raise PolicyModelError(f"policy model {path}: input width {width_in} but the metadata names "
                               f"{md.observation.size} observations")
    if width_out != md.action.size:
        raise PolicyModelError(f"policy model {path}: output width {width_out} but the metadata names "
                               f"{md.action.size} actions")
    return session, md


def resolve_model_path(path: str) -> Path:
    """`package://<package>/<path>` under that package's share directory (AMENT_PREFIX_PATH);
    anything else as a file path."""
    if path.startswith("package://"):
        package, _, rest = path[len("package://"):].partition("/")
        for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
            if prefix and (Path(prefix) / "share" / package / rest).is_file():
                return Path(prefix) / "share" / package / rest
        raise PolicyModelError(f"policy model {path}: not found in the share directory of '{package}'")
    return Path(path).expanduser()


class PolicyRunner:
    def __init__(self, session, metadata: PolicyMetadata, where: str = "model"):
        self.session, self.metadata, self.where = session, metadata, where
        o, a = metadata.observation, metadata.action
        self.mean = np.asarray(o.mean, dtype=np.float64)
        self.inv_std = 1.0 / np.asarray(o.std, dtype=np.float64)
        self.scale = np.asarray(a.scale, dtype=np.float64)
        self.low = np.asarray(a.low, dtype=np.float64)
        self.high = np.asarray(a.high, dtype=np.float64)
        self.input_name = session.get_inputs()[0].name
        self._buf = np.zeros((1, o.size), dtype=np.float32)
        self.last_inference_s = 0.0

    @classmethod
    def load(cls, path, observation_names: Optional[Sequence[str]] = None, action_kind: Optional[str] = None,
             action_count: Optional[int] = None, rate_hz: Optional[float] = None) -> PolicyRunner:
        path = resolve_model_path(path) if isinstance(path, str) else Path(path)
        session, md = read_model(path)
        where = str(path)
        if observation_names is not None and list(observation_names) != list(md.observation.names):
            expected, got = list(observation_names), list(md.observation.names)
            diff = next((i for i, (a, b) in enumerate(zip(expected, got)) if a != b), min(len(expected), len(got)))
            raise PolicyModelError(
                f"policy model {where}: takes {len(got)} observations, this controller gives {len(expected)} "
                f"(first difference at {diff}: model {got[diff] if diff < len(got) else '-'!r}, controller "
                f"{expected[diff] if diff < len(expected) else '-'!r})")
        if action_kind is not None and md.action.kind != action_kind:
            raise PolicyModelError(f"policy model {where}: action kind {md.action.kind!r}, this controller needs "
                                   f"{action_kind!r}")
        if action_count is not None and md.action.size != action_count:
            raise PolicyModelError(f"policy model {where}: {md.action.size} actions, this controller needs "
                                   f"{action_count}")
        if rate_hz is not None and not math.isclose(md.rate_hz, rate_hz, rel_tol=1e-6):
            raise PolicyModelError(f"policy model {where}: trained at {md.rate_hz:g} Hz, configured at "
                                   f"{rate_hz:g} Hz (its observation history assumes its own rate)")
        return cls(session, md, where)

    def infer(self, obs) -> Optional[np.ndarray]:
        """Raw action (n_act,) in [-1, 1] for the raw observation (n_obs,); None when the
        observation or the result is not finite (nothing of it may reach a command)."""
        obs = np.asarray(obs, dtype=np.float64).reshape(-1)
        if obs.shape[0] != self.mean.shape[0] or not np.all(np.isfinite(obs)):
            return None
        np.multiply(obs - self.mean, self.inv_std, out=self._buf[0], casting="same_kind")
        t0 = time.perf_counter()
        out = self.session.run(None, {self.input_name: self._buf})[0]
        self.last_inference_s = time.perf_counter() - t0
        action = np.asarray(out, dtype=np.float64).reshape(-1)
        if not np.all(np.isfinite(action)):
            return None
        return action

    def command(self, action, base=None) -> np.ndarray:
        """action * scale (+ base for a residual model), clamped to the model's [low, high]."""
        value = np.asarray(action, dtype=np.float64) * self.scale
        if base is not None:
            value = value + np.asarray(base, dtype=np.float64)
        return np.clip(value, self.low, self.high)
