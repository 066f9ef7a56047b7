"""Parameter schemas: declared once, validated once, handed to the hot path as a frozen snapshot.

A node or controller lists its parameters as `Param` entries (name, default, unit, bounds,
description). `declare_parameters` declares them on an rclpy node (with descriptors, so
`ros2 param describe` shows them) and returns a validated, immutable snapshot; a bad value
raises `ParameterError` naming the parameter, which `run_node` turns into one clear line at
start-up. `validate` does the same for a plain dict (no ROS), for tests and tools.

`report_unknown_parameters` catches the other mistake: a value given to a node (parameter
file or `-p`) under a name it never declares, e.g. `kp_typo`, which rclpy keeps silently. It
logs one warning naming them (and the closest declared name), or refuses to start when the
node's `unknown_parameters` parameter is `error`. A name a parameter had before it was renamed
(`Param.formerly`) is named with its new name instead of a guess.
"""
from __future__ import annotations

import array
import difflib
import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Callable, Iterable, List, Mapping, Optional, Sequence


class ParameterError(ValueError):
    """A parameter value is missing, of the wrong type, or out of its bounds."""


@dataclass(frozen=True)
class Param:
    """One parameter: its name, default (which fixes its type), and what it accepts."""

    name: str
    default: Any
    description: str = ""
    unit: str = ""
    min: Optional[float] = None
    max: Optional[float] = None
    choices: Optional[Sequence[Any]] = None
    read_only: bool = False
    user_facing: bool = False
    """A setting a user sets for their own setup (device, geometry, task, main gains); the others are
    advanced: their defaults suit every setup tested, docs list them after the user-facing ones."""
    check: Optional[Callable[[Any], Optional[str]]] = field(default=None, compare=False)
    """Extra check: returns an error message, or None when the value is fine."""
    formerly: Sequence[str] = ()
    """Names this parameter had before (a value given under one is reported with this name)."""

    def validate(self, value: Any) -> Any:
        """Return `value` coerced to this parameter's type, or raise ParameterError."""
        value = _coerce(self, value)
        problem = None
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            if isinstance(value, float) and not math.isfinite(value):
                problem = "must be finite"
            elif self.min is not None and value < self.min:
                problem = f"must be >= {self.min}"
            elif self.max is not None and value > self.max:
                problem = f"must be <= {self.max}"
        if problem is None and self.choices is not None and value not in self.choices:
            problem = f"must be one of {list(self.choices)}"
        if problem is None and self.check is not None:
            problem = self.check(value)
        if problem:
            raise ParameterError(f"parameter '{self.name}' = {value!r} {problem}")
        return value


def _coerce(param: Param, value: Any) -> Any:
    default = param.default
    try:
        if isinstance(default, bool):
            if isinstance(value, bool):
                return value
        elif isinstance(default, int):
            if isinstance(value, int) and not isinstance(value, bool):
                return value
        elif isinstance(default, float):
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                return float(value)
        elif isinstance(default, str):
            if isinstance(value, str):
                return value
        elif isinstance(default, (list, tuple)):
            # rclpy hands a double/integer array set at run time (set_parameters) as array.array
            if isinstance(value, (list, tuple, array.array)):
                if default and isinstance(default[0], float):
                    return tuple(float(v) for v in value)
                return tuple(value)
    except (TypeError, ValueError):
        pass
    expected = type(default).__name__ if not isinstance(default, (list, tuple)) else "list"
    if value is None and isinstance(default, (list, tuple)):  # what rcl makes of `-p name:=[]`
        raise ParameterError(f"parameter '{param.name}' = [] has no type in ROS (an empty list is not a "
                             f"parameter value): give it at least one element")
    raise ParameterError(f"parameter '{param.name}' = {value!r} must be of type {expected}")


def validate(schema: Iterable[Param], values: Mapping[str, Any] | None = None,
             allow_unknown: bool = False) -> Mapping[str, Any]:
    """Validate `values` against `schema`, filling defaults. Returns a read-only mapping."""
    values = dict(values or {})
    schema = list(schema)
    known = {p.name for p in schema}
    unknown = sorted(set(values) - known)
    if unknown and not allow_unknown:
        raise ParameterError(f"unknown parameter(s): {describe_unknown(unknown, known, renamed_names(schema))}")
    return MappingProxyType({p.name: p.validate(values.get(p.name, p.default)) for p in schema})


def declare_parameters(node, schema: Iterable[Param]) -> Mapping[str, Any]:
    """Declare `schema` on an rclpy node and return the validated values (read-only)."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

    schema = list(schema)
    # kept on the node for report_unknown_parameters: a value under a former name says the new one
    node.__dict__.setdefault("_former_parameter_names", {}).update(renamed_names(schema))
    values = {}
    for p in schema:
        descriptor = ParameterDescriptor(
            description=f"{p.description} [{p.unit}]" if p.unit else p.description,
            read_only=p.read_only)
        if p.min is not None and p.max is not None and not isinstance(p.default, bool):
            if isinstance(p.default, float):
                descriptor.floating_point_range = [FloatingPointRange(from_value=float(p.min), to_value=float(p.max))]
            elif isinstance(p.default, int):
                descriptor.integer_range = [IntegerRange(from_value=int(p.min), to_value=int(p.max))]
        default = list(p.default) if isinstance(p.default, tuple) else p.default
        try:
            value = node.declare_parameter(p.name, default, descriptor).value
        except Exception as error:  # rclpy raises several types for a bad override
            given = getattr(node, "_parameter_overrides", {}).get(p.name)
            if given is not None:
                p.validate(given.value)  # our own words for it (range, type), when they find it
            raise ParameterError(f"parameter '{p.name}': {error}") from None
        values[p.name] = p.validate(value)
    return MappingProxyType(values)


UNKNOWN_PARAMETERS = Param(
    "unknown_parameters", "warn",
    "a value given to this node (parameter file or -p) for a parameter it does not declare: "
    "'warn' logs the names, 'error' refuses to start", choices=("warn", "error"), read_only=True)


def unknown_parameter_names(given: Iterable[str], declared: Iterable[str]) -> List[str]:
    """The names in `given` that are not `declared` (sorted)."""
    return sorted(set(given) - set(declared))


def renamed_names(schema: Iterable[Param]) -> Mapping[str, str]:
    """Former name -> current name, for the parameters of `schema` that were renamed."""
    return {old: p.name for p in schema for old in p.formerly}


def closest_name(name: str, declared: Iterable[str]) -> Optional[str]:
    """The declared name `name` was probably meant to be (kp_typo -> kp), or None."""
    declared = sorted(declared)
    close = difflib.get_close_matches(name, declared, n=1, cutoff=0.6) or \
        [d for d in declared if name.startswith(f"{d}_")][-1:]
    return close[0] if close else None


def describe_unknown(unknown: Sequence[str], declared: Iterable[str],
                     renamed: Optional[Mapping[str, str]] = None) -> str:
    """'kp_typo (did you mean kp?), grace_s (renamed loss_hold_s), foo' for a message."""
    declared = list(declared)
    renamed = renamed or {}
    parts = []
    for name in unknown:
        if name in renamed:
            parts.append(f"{name} (renamed {renamed[name]})")
            continue
        close = closest_name(name, declared)
        parts.append(f"{name} (did you mean {close}?)" if close else name)
    return ", ".join(parts)


def report_unknown_parameters(node) -> List[str]:
    """Check the values given to `node` against what it declared; call once it declared them all.

    Returns the unknown names. Logs one warning naming them, or raises ParameterError when
    the node's `unknown_parameters` parameter (declared here if the node has not) is 'error'.
    """
    if not node.has_parameter(UNKNOWN_PARAMETERS.name):
        declare_parameters(node, [UNKNOWN_PARAMETERS])
    policy = UNKNOWN_PARAMETERS.validate(node.get_parameter(UNKNOWN_PARAMETERS.name).value)
    declared = list(node._parameters)  # rclpy keeps overrides apart from declared parameters
    unknown = unknown_parameter_names(getattr(node, "_parameter_overrides", {}), declared)
    if not unknown:
        return unknown
    names = describe_unknown(unknown, declared, getattr(node, "_former_parameter_names", None))
    text = (f"unknown parameter(s) given to {node.get_fully_qualified_name()}: {names} "
            "(not declared by this node; `ros2 param list` shows the declared ones)")
    if policy == "error":
        raise ParameterError(f"{text}; unknown_parameters is 'error'")
    node.get_logger().warning(f"{text}: ignored")
    return unknown
