"""Parameter schemas: declared once, validated once, handed to the hot path as a frozen snapshot.

A node or controller lists its parameters as `Param` entries (name, default, unit, bounds,
description). `declare_parameters` declares them on an rclpy node (with descriptors, so
`ros2 param describe` shows them) and returns a validated, immutable snapshot; a bad value
raises `ParameterError` naming the parameter, which `run_node` turns into one clear line at
start-up. `validate` does the same for a plain dict (no ROS), for tests and tools.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Callable, Iterable, Mapping, Optional, Sequence


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
    check: Optional[Callable[[Any], Optional[str]]] = field(default=None, compare=False)
    """Extra check: returns an error message, or None when the value is fine."""

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
            if isinstance(value, (list, tuple)):
                if default and isinstance(default[0], float):
                    return tuple(float(v) for v in value)
                return tuple(value)
    except (TypeError, ValueError):
        pass
    expected = type(default).__name__ if not isinstance(default, (list, tuple)) else "list"
    raise ParameterError(f"parameter '{param.name}' = {value!r} must be of type {expected}")


def validate(schema: Iterable[Param], values: Mapping[str, Any] | None = None,
             allow_unknown: bool = False) -> Mapping[str, Any]:
    """Validate `values` against `schema`, filling defaults. Returns a read-only mapping."""
    values = dict(values or {})
    schema = list(schema)
    known = {p.name for p in schema}
    unknown = sorted(set(values) - known)
    if unknown and not allow_unknown:
        raise ParameterError(f"unknown parameter(s): {', '.join(unknown)}")
    return MappingProxyType({p.name: p.validate(values.get(p.name, p.default)) for p in schema})


def declare_parameters(node, schema: Iterable[Param]) -> Mapping[str, Any]:
    """Declare `schema` on an rclpy node and return the validated values (read-only)."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

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
            raise ParameterError(f"parameter '{p.name}': {error}") from None
        values[p.name] = p.validate(value)
    return MappingProxyType(values)
