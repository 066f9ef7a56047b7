"""Message types by name, messages to YAML (as `ros2 topic echo` prints them) and back.

rosidl_runtime_py is not on PyPI, so this is our own small version of its helpers: type
lookup through `importlib` on `<pkg>.msg` / `<pkg>.srv`, message -> ordered dict -> YAML, and
dict (parsed YAML) -> message fields with one-line errors naming the field.
"""
from __future__ import annotations

import importlib
import re
import sys
from collections import OrderedDict
from typing import Any, Optional

from ball_balance.cli.errors import CliError

_PRIMITIVE_FLOATS = {"float", "double", "float32", "float64"}


def split_type_name(type_name: str, default_kind: str = "msg"):
    """'pkg/msg/Type', 'pkg/Type' or 'pkg.msg.Type' -> (pkg, kind, Type)."""
    parts = [p for p in re.split(r"[/.]", type_name.strip()) if p]
    if len(parts) == 2:
        parts = [parts[0], default_kind, parts[1]]
    if len(parts) != 3 or parts[1] not in ("msg", "srv", "action"):
        raise CliError(f"'{type_name}' is not a valid interface type name (expected package/{default_kind}/Type)")
    return parts[0], parts[1], parts[2]


def get_interface(type_name: str, default_kind: str = "msg"):
    """The Python class of a message or service type, e.g. 'std_msgs/msg/String'."""
    pkg, kind, name = split_type_name(type_name, default_kind)
    try:
        module = importlib.import_module(f"{pkg}.{kind}")
    except ImportError:
        raise CliError(f"unknown {kind} type '{type_name}': no interface package '{pkg}' is installed") from None
    cls = getattr(module, name, None)
    expected = "Request" if kind == "srv" else "get_fields_and_field_types"
    if not isinstance(cls, type) or not hasattr(cls, expected):
        raise CliError(f"unknown {kind} type '{type_name}': package '{pkg}' has no {kind} '{name}'")
    return cls


def type_name_of(msg_or_cls) -> str:
    """'pkg/msg/Type' of a message class or instance."""
    cls = msg_or_cls if isinstance(msg_or_cls, type) else type(msg_or_cls)
    parts = cls.__module__.split(".")
    return f"{parts[0]}/{parts[1]}/{cls.__name__}"


def is_message(value: Any) -> bool:
    return hasattr(value, "get_fields_and_field_types")


# --- message -> YAML ---------------------------------------------------------------------
# As rosidl_runtime_py's message_to_ordereddict (Jazzy) renders them, which `ros2 topic echo`
# and `ros2 action send_goal` print through yaml.dump:
# - bytes (a `byte`/`octet` field, which rclpy gives as a bytes of length 1, and the items of
#   a `byte[]`, a list of them) become a text string of one character per byte (chr(b)), so
#   b'\x02' prints as `"\x02"` and b'A' as `A`; longer than the truncate length: cut, '...' added.
#   `uint8`/`char` fields are ints and print as numbers (`uint8[]`: array.array, numpy array).
# - --no-arr abbreviates an array field by its declared type: `<array type: double[3]>`,
#   `<sequence type: octet[8], length: 2>` (bounded) or `<sequence type: octet, length: 2>`.
def message_to_ordered(value: Any, truncate_length: Optional[int] = None, no_arr: bool = False,
                       no_str: bool = False, field_type: Any = None) -> Any:
    """Message (or field value) -> plain OrderedDict / list / scalar, for YAML output.

    field_type: the rosidl_parser type of the field `value` comes from (a message's SLOT_TYPES
    entry), which --no-arr names; a bare value has none and is never abbreviated.
    """
    if is_message(value):
        fields = value.get_fields_and_field_types()
        slot_types = getattr(value, "SLOT_TYPES", None) or [None] * len(fields)
        return OrderedDict((name, message_to_ordered(getattr(value, name), truncate_length, no_arr, no_str, slot))
                           for name, slot in zip(fields, slot_types, strict=False))
    if isinstance(value, bytes):
        text = "".join(map(chr, value))
        if truncate_length is not None and len(text) > truncate_length:
            return text[:truncate_length] + "..."
        return text
    if isinstance(value, str):
        if no_str:
            return f"<string length: <{len(value)}>>"
        if truncate_length is not None and len(value) > truncate_length:
            return value[:truncate_length] + "..."
        return value
    if hasattr(value, "tolist") or isinstance(value, (list, tuple)):  # array.array, numpy, sequences
        if no_arr and field_type is not None:
            return _abbreviated_array(value, field_type)
        items = value.tolist() if hasattr(value, "tolist") else list(value)
        truncated = truncate_length is not None and len(items) > truncate_length
        if truncated:
            items = items[:truncate_length]
        items = [message_to_ordered(item, truncate_length, no_arr, no_str) for item in items]
        return items + ["..."] if truncated else items
    if hasattr(value, "item"):  # numpy scalar
        return value.item()
    return value


def _abbreviated_array(value: Any, field_type: Any) -> str:
    """What --no-arr prints instead of an array field, named by its declared type."""
    from rosidl_parser import definition

    element = field_type.value_type if isinstance(field_type, definition.AbstractNestedType) else None
    if isinstance(element, definition.BasicType):
        element_name = element.typename
    elif isinstance(element, definition.AbstractString):
        element_name = "string"
    elif isinstance(element, definition.AbstractWString):
        element_name = "wstring"
    elif isinstance(element, definition.NamespacedType):
        element_name = "/".join(element.namespaced_name())
    elif isinstance(element, definition.NamedType):
        element_name = element.name
    else:
        element_name = "unknown"
    if isinstance(field_type, definition.Array):
        return f"<array type: {element_name}[{field_type.size}]>"
    if isinstance(field_type, definition.BoundedSequence):
        return f"<sequence type: {element_name}[{field_type.maximum_size}], length: {len(value)}>"
    if isinstance(field_type, definition.UnboundedSequence):
        return f"<sequence type: {element_name}, length: {len(value)}>"
    return "unknown"


def to_yaml(value: Any) -> str:
    """YAML text like ros2cli prints it (block style, field order kept, no line wrapping)."""
    import yaml

    class Dumper(yaml.SafeDumper):
        pass

    Dumper.add_representer(OrderedDict, lambda d, data: d.represent_mapping(
        "tag:yaml.org,2002:map", data.items()))
    return yaml.dump(value, Dumper=Dumper, default_flow_style=False, allow_unicode=True,
                     width=sys.maxsize, sort_keys=False)


def message_to_yaml(msg: Any, truncate_length: Optional[int] = 128, no_arr: bool = False,
                    no_str: bool = False) -> str:
    text = to_yaml(message_to_ordered(msg, truncate_length, no_arr, no_str))
    if not is_message(msg) and text.endswith("\n...\n"):  # a bare scalar: no document end marker
        text = text[:-4]
    return text


def echo_text(value: Any, truncate_length: Optional[int] = 128, no_arr: bool = False,
              no_str: bool = False) -> str:
    """One `ros2 topic echo` output (without the '---' line): a message as YAML; a field that is
    not a message (--field) as Python's str() of it, untruncated, as ros2cli prints it (e.g.
    `b'\\x02'` for a byte field, `array('d', [1.0, 2.0])` for a float64[])."""
    if is_message(value):
        return message_to_yaml(value, truncate_length, no_arr, no_str)
    return f"{value}\n"


def get_field(msg: Any, path: str) -> Any:
    """msg.a.b for path 'a.b' (a CliError naming the missing part)."""
    value = msg
    for part in [p for p in path.split(".") if p]:
        if not is_message(value) or part not in value.get_fields_and_field_types():
            raise CliError(f"invalid field '{path}': {type_name_of(value) if is_message(value) else 'value'} "
                           f"has no field '{part}'")
        value = getattr(value, part)
    return value


# --- dict -> message -------------------------------------------------------------------
def parse_yaml_values(text: str, what: str = "message values") -> Any:
    """YAML text -> Python value; a CliError with the parser's first line when malformed."""
    from controller_manager_py.ros.params_files import ParamsFileError, load_yaml_text

    try:
        return load_yaml_text(text, what)
    except ParamsFileError as error:
        raise CliError(str(error)) from None


def set_message_fields(msg: Any, values: Any, path: str = "", now_ns: Optional[int] = None) -> Any:
    """Fill msg from a dict of field values (nested dicts for nested messages).

    Special values as in ros2 topic pub: 'now' for a builtin_interfaces/Time field, 'auto'
    for a std_msgs/Header field (stamp = now).
    """
    type_name = type_name_of(msg)
    if values is None:
        return msg
    if not isinstance(values, dict):
        raise CliError(f"values for {path or type_name} must be a mapping of field names, got {values!r}")
    fields = msg.get_fields_and_field_types()
    for name, value in values.items():
        where = f"{path}.{name}" if path else str(name)
        if name not in fields:
            raise CliError(f"{type_name} has no field '{where}' (fields: {', '.join(fields)})")
        field_type = fields[name]
        current = getattr(msg, name)
        try:
            setattr(msg, name, _convert(current, field_type, value, where, now_ns))
        except CliError:
            raise
        except (AssertionError, TypeError, ValueError, OverflowError) as error:
            detail = str(error).splitlines()[0] if str(error) else f"{value!r} does not fit {field_type}"
            raise CliError(f"bad value for field '{where}' ({field_type}): {detail}") from None
    return msg


def _convert(current: Any, field_type: str, value: Any, where: str, now_ns: Optional[int]) -> Any:
    if is_message(current):
        nested_type = type_name_of(current)
        if nested_type == "builtin_interfaces/msg/Time" and value == "now":
            return _time_now(type(current), now_ns)
        if nested_type == "std_msgs/msg/Header" and value == "auto":
            header = type(current)()
            header.stamp = _time_now(type(header.stamp), now_ns)
            return header
        return set_message_fields(type(current)(), value, where, now_ns)
    element = _sequence_element(field_type)
    if element is not None:
        if not isinstance(value, (list, tuple)):
            raise CliError(f"bad value for field '{where}' ({field_type}): expected a list, got {value!r}")
        if "/" in element:  # a sequence of messages
            cls = get_interface(element)
            return [_convert(cls(), element, item, f"{where}[{i}]", now_ns) for i, item in enumerate(value)]
        return [_scalar(element, item, f"{where}[{i}]") for i, item in enumerate(value)]
    return _scalar(field_type, value, where)


def _sequence_element(field_type: str) -> Optional[str]:
    """'sequence<double, 3>' / 'double[3]' / 'sequence<pkg/Type>' -> element type, else None."""
    match = re.fullmatch(r"sequence<([^,>]+)(?:,\s*\d+)?>", field_type)
    if match:
        return match.group(1).strip()
    match = re.fullmatch(r"(.+)\[\d*\]", field_type)
    return match.group(1) if match else None


_INT_BITS = {"int8": (8, True), "uint8": (8, False), "int16": (16, True), "uint16": (16, False),
             "int32": (32, True), "uint32": (32, False), "int64": (64, True), "uint64": (64, False),
             "char": (8, False), "octet": (8, False), "byte": (8, False)}


def _scalar(field_type: str, value: Any, where: str) -> Any:
    """Check and convert one primitive value (generated setters do not check by default)."""
    base = field_type.split("<")[0]

    def bad(expected: str):
        return CliError(f"bad value for field '{where}' ({field_type}): expected {expected}, got {value!r}")

    if base in ("string", "wstring"):
        if not isinstance(value, str):
            raise bad("a string")
        return value
    if base in ("boolean", "bool"):
        if not isinstance(value, bool):
            raise bad("true or false")
        return value
    if base in _PRIMITIVE_FLOATS:
        if isinstance(value, str):  # YAML 1.1 reads 1e308 (no dot) as a string; YAML 1.2 and ros2 as a number
            try:
                return float(value)
            except ValueError:
                raise bad("a number") from None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise bad("a number")
        return float(value)
    if base in _INT_BITS:
        if base in ("byte", "octet") and isinstance(value, bytes) and len(value) == 1:
            return value
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad("an integer")
        bits, signed = _INT_BITS[base]
        low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
        if not low <= value <= high:
            raise CliError(f"bad value for field '{where}' ({field_type}): {value} is outside [{low}, {high}]")
        return bytes([value]) if base in ("byte", "octet") else value
    return value


def _time_now(time_cls, now_ns: Optional[int]):
    import time

    ns = now_ns if now_ns is not None else time.time_ns()
    return time_cls(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
