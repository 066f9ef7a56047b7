"""Parameters of the learned policy's tilt law (added to the PID's: the policy is a residual on it)."""
from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

from ball_balance.control.config import PID_SCHEMA
from controller_manager_py.parameters import Param

PACKAGE = "ball_balance"
DEFAULT_MODEL = "policies/residual_tilt.onnx"

POLICY_PARAMS = [
    Param("policy_model", DEFAULT_MODEL, "ONNX policy model: absolute, or relative to the package's config/ "
          "folder", read_only=True, user_facing=True),
    Param("policy_blend_s", 1.0, "after every engagement, ramp the policy's correction in from 0 over this "
          "long (0: at once)", "s", 0.0, 30.0, read_only=True),
    Param("policy_max_delay_s", 0.17, "the policy's correction applies in full up to this command-to-plate "
          "delay (the pipeline's estimate) and fades out over the next 20 ms: beyond it the PID alone (0: at "
          "any delay)", "s", 0.0, 1.0, read_only=True),
]

DEFAULT_MODEL_RATE_HZ = 60.0   # the rate DEFAULT_MODEL was trained at (its metadata's rate_hz)


def _for_the_policy(param: Param) -> Param:
    """The PID's parameter as the policy node declares it: its history is per tick of the
    model's rate, so it steps on the timer only, at that rate."""
    if param.name == "control_rate_hz":
        return replace(param, default=DEFAULT_MODEL_RATE_HZ,
                       description=f"{param.description}: the model's (its metadata's rate_hz; another is "
                                   "refused at start-up)")
    if param.name == "control_trigger":
        return Param("control_trigger", "timer", "the policy steps every control_rate_hz tick (its history is "
                     "per tick)", choices=("timer",), read_only=True)
    return param


# the policy node: a correction on top of the PID, so the PID's parameters plus the model's
POLICY_SCHEMA = [_for_the_policy(p) for p in PID_SCHEMA] + POLICY_PARAMS


def model_path(value: str) -> Path:
    """policy_model as a file: absolute as given; relative under config/ of the installed share
    directory, else of the source tree (as the robot description is found)."""
    path = Path(value).expanduser()
    if path.is_absolute():
        return path
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix and (Path(prefix) / "share" / PACKAGE / "config" / path).is_file():
            return Path(prefix) / "share" / PACKAGE / "config" / path
    return Path(__file__).resolve().parents[2] / "config" / path
