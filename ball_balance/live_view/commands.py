"""What the live view's page may ask for, checked before anything reaches the graph.

The page sends one JSON object per request: {"id": n, "op": ..., ...}. `parse` turns it into a
`Command` (or raises CommandError with one line naming what is wrong):

  {"op": "lifecycle", "transition": "configure" | "activate" | "deactivate" | "cleanup"}
      the robot manager's lifecycle transition (lifecycle_msgs/srv/ChangeState)
  {"op": "emergency_stop"}, {"op": "reset_emergency_stop"}
      the robot manager's std_srvs/srv/Trigger services
  {"op": "set_parameters", "values": {"kp": 2.0, ...}}
      the balance controller's parameters (rcl_interfaces/srv/SetParameters); only the names
      the node allows (its `gain_names` and the reference parameters) and finite numbers
  {"op": "reference", "kind": "circle", "centre_m": [x, y], "radius_m": r, "period_s": T}
      the controller's reference_* parameters; every field but "kind" optional
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, Iterable, Optional

# lifecycle_msgs/msg/Transition ids (public definition)
TRANSITIONS = {"configure": 1, "cleanup": 2, "activate": 3, "deactivate": 4}
TRIGGERS = ("emergency_stop", "reset_emergency_stop")
REFERENCE_KINDS = ("stationary", "circle", "figure_eight", "square", "step")
PLATE_HALF_M = 0.2285          # plate half side: a reference centre beyond it is refused
MAX_TEXT = 2000                # longest request the page may send (bytes)


class CommandError(ValueError):
    """A request the live view refuses (the message says why, in one line)."""


@dataclass(frozen=True)
class Command:
    op: str                                   # "lifecycle", "trigger", "set_parameters"
    name: str = ""                            # transition label or trigger service name
    transition_id: int = 0
    values: Dict[str, Any] = field(default_factory=dict)   # parameter name -> value

    def describe(self) -> str:
        if self.op == "set_parameters":
            return "set " + ", ".join(f"{k}={_show(v)}" for k, v in self.values.items())
        return self.name.replace("_", " ")


def _show(value) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(_show(v) for v in value) + "]"
    return f"{value:g}" if isinstance(value, float) else str(value)


def _number(value, what: str, low: float = -math.inf, high: float = math.inf) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CommandError(f"{what} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise CommandError(f"{what} must be finite, got {value}")
    if not low <= value <= high:
        raise CommandError(f"{what} {value:g} is outside [{low:g}, {high:g}]")
    return value


def parse(request: Any, gain_names: Iterable[str]) -> Command:
    """A request from the page -> Command; CommandError when it is malformed or not allowed."""
    if not isinstance(request, dict):
        raise CommandError("a request must be a JSON object")
    op = request.get("op")
    if op == "lifecycle":
        transition = request.get("transition")
        if transition not in TRANSITIONS:
            raise CommandError(f"unknown transition {transition!r} (one of {', '.join(TRANSITIONS)})")
        return Command("lifecycle", transition, TRANSITIONS[transition])
    if op in TRIGGERS:
        return Command("trigger", op)
    if op == "set_parameters":
        values = request.get("values")
        if not isinstance(values, dict) or not values:
            raise CommandError("set_parameters needs a non-empty object 'values'")
        allowed = tuple(gain_names)
        checked = {}
        for name, value in values.items():
            if name not in allowed:
                raise CommandError(f"parameter {name!r} cannot be set from the page (allowed: {', '.join(allowed)})")
            checked[name] = _number(value, name, 0.0)
        return Command("set_parameters", values=checked)
    if op == "reference":
        return Command("set_parameters", values=reference_values(request))
    raise CommandError(f"unknown op {op!r}")


def reference_values(request: Dict[str, Any]) -> Dict[str, Any]:
    """The controller's reference_* parameters for a reference request."""
    kind = request.get("kind")
    if kind not in REFERENCE_KINDS:
        raise CommandError(f"unknown reference kind {kind!r} (one of {', '.join(REFERENCE_KINDS)})")
    values: Dict[str, Any] = {"reference_kind": kind}
    centre: Optional[list] = request.get("centre_m")
    if centre is not None:
        if not isinstance(centre, list) or len(centre) != 2:
            raise CommandError("centre_m must be [x, y] in metres")
        values["reference_centre_m"] = [_number(c, "centre_m", -PLATE_HALF_M, PLATE_HALF_M) for c in centre]
    if request.get("radius_m") is not None:
        values["reference_radius_m"] = _number(request["radius_m"], "radius_m", 0.0, 0.2)
    if request.get("period_s") is not None:
        values["reference_period_s"] = _number(request["period_s"], "period_s", 0.5, 600.0)
    return values
