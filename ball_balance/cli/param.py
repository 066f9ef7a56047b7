"""`ros2py param get|set|dump|list|load` through a node's rcl_interfaces services."""
from __future__ import annotations

from typing import Any, Dict, List

from ball_balance.cli.errors import CliError
from ball_balance.cli.session import Session, full_node_name
from controller_manager_py.text_files import TextFileError, read_text_file

# ParameterType constants (rcl_interfaces/msg/ParameterType) -> (ParameterValue field, ros2 label)
_TYPES = {
    1: ("bool_value", "Boolean value is:"),
    2: ("integer_value", "Integer value is:"),
    3: ("double_value", "Double value is:"),
    4: ("string_value", "String value is:"),
    5: ("byte_array_value", "Byte values are:"),
    6: ("bool_array_value", "Boolean values are:"),
    7: ("integer_array_value", "Integer values are:"),
    8: ("double_array_value", "Double values are:"),
    9: ("string_array_value", "String values are:"),
}


def value_to_python(value) -> Any:
    """rcl_interfaces/ParameterValue -> Python (None when not set)."""
    if value.type not in _TYPES:
        return None
    field = getattr(value, _TYPES[value.type][0])
    return list(field) if value.type >= 5 else field


def python_to_value(data: Any, name: str = "value"):
    """Python value (parsed YAML) -> rcl_interfaces/ParameterValue; CliError for other types."""
    from rcl_interfaces.msg import ParameterType, ParameterValue

    value = ParameterValue()
    if isinstance(data, bool):
        value.type, value.bool_value = ParameterType.PARAMETER_BOOL, data
    elif isinstance(data, int):
        value.type, value.integer_value = ParameterType.PARAMETER_INTEGER, data
    elif isinstance(data, float):
        value.type, value.double_value = ParameterType.PARAMETER_DOUBLE, data
    elif isinstance(data, str):
        value.type, value.string_value = ParameterType.PARAMETER_STRING, data
    elif isinstance(data, (list, tuple)) and data:
        kinds = {type(v) for v in data}
        if kinds == {bool}:
            value.type, value.bool_array_value = ParameterType.PARAMETER_BOOL_ARRAY, list(data)
        elif kinds == {int}:
            value.type, value.integer_array_value = ParameterType.PARAMETER_INTEGER_ARRAY, list(data)
        elif kinds <= {int, float} and float in kinds:
            value.type, value.double_array_value = ParameterType.PARAMETER_DOUBLE_ARRAY, [float(v) for v in data]
        elif kinds == {str}:
            value.type, value.string_array_value = ParameterType.PARAMETER_STRING_ARRAY, list(data)
        else:
            raise CliError(f"parameter '{name}': a list must hold one type (bool, int, float or string), got {data!r}")
    else:
        raise CliError(f"parameter '{name}': cannot set {data!r} (use a bool, int, float, string or a list of one)")
    return value


def _service(session: Session, node: str, name: str, srv_type, request):
    session.wait_for_node(node, session.spin_time_s)
    return session.call(srv_type, f"{node}/{name}", request, timeout_s=max(session.spin_time_s, 5.0))


def _open(args) -> Session:
    return Session(max(args.spin_time, 0.5))


def get_values(session: Session, node: str, names: List[str]) -> List[Any]:
    from rcl_interfaces.srv import GetParameters

    response = _service(session, node, "get_parameters", GetParameters, GetParameters.Request(names=names))
    return list(response.values)


def list_names(session: Session, node: str) -> List[str]:
    from rcl_interfaces.srv import ListParameters

    response = _service(session, node, "list_parameters", ListParameters, ListParameters.Request())
    return sorted(response.result.names)


def set_values(session: Session, node: str, values: Dict[str, Any]) -> List[Any]:
    from rcl_interfaces.msg import Parameter
    from rcl_interfaces.srv import SetParameters

    request = SetParameters.Request(parameters=[
        Parameter(name=name, value=python_to_value(value, name)) for name, value in values.items()])
    return list(_service(session, node, "set_parameters", SetParameters, request).results)


def undeclared(session: Session, node: str, name: str, prefix: str) -> CliError:
    """The one line for a name the node has not declared, with the closest declared one."""
    from controller_manager_py.parameters import closest_name

    close = closest_name(name, list_names(session, node))
    hint = f"did you mean {close}? " if close else ""
    return CliError(f"{prefix}'{name}' is not declared by {node} "
                    f"({hint}`ros2py param list {node}` shows its parameters)")


def cmd_get(args) -> int:
    node = full_node_name(args.node_name)
    with _open(args) as session:
        (value,) = get_values(session, node, [args.parameter_name]) or [None]
    if value is None or value.type not in _TYPES:
        raise CliError(f"parameter '{args.parameter_name}' is not set on node '{node}'")
    field, label = _TYPES[value.type]
    shown = getattr(value, field)
    print(shown if args.hide_type else f"{label} {shown}")
    return 0


def cmd_set(args) -> int:
    from ball_balance.cli.messages import parse_yaml_values

    node = full_node_name(args.node_name)
    data = parse_yaml_values(args.value, what=f"the value for '{args.parameter_name}'")
    with _open(args) as session:
        (result,) = set_values(session, node, {args.parameter_name: data})
        if not result.successful and "undeclared" in result.reason:
            # rclpy's reason lists no name ("undeclared parameter(s): []"): say which, and what is close
            raise undeclared(session, node, args.parameter_name, "Setting parameter failed: ")
    if not result.successful:
        raise CliError(f"Setting parameter failed: {result.reason or 'refused by the node'}")
    print("Set parameter successful")
    return 0


def nest(flat: Dict[str, Any]) -> Dict[str, Any]:
    """{'a.b': 1, 'c': 2} -> {'a': {'b': 1}, 'c': 2} (as parameter files are written)."""
    tree: Dict[str, Any] = {}
    for name, value in sorted(flat.items()):
        node = tree
        *parents, leaf = name.split(".")
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value
    return tree


def flatten(tree: Dict[str, Any], prefix: str = "") -> Dict[str, Any]:
    """The inverse of nest."""
    flat: Dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten(value, f"{name}."))
        else:
            flat[name] = value
    return flat


def cmd_dump(args) -> int:
    import yaml

    node = full_node_name(args.node_name)
    with _open(args) as session:
        names = list_names(session, node)
        values = get_values(session, node, names) if names else []
    params = {name: value_to_python(v) for name, v in zip(names, values, strict=True)}
    print(yaml.safe_dump({node: {"ros__parameters": nest(params)}}, default_flow_style=False,
                         sort_keys=False), end="")
    return 0


# rcl_interfaces/msg/ParameterType -> the name ros2cli prints
_TYPE_NAMES = ("not set", "boolean", "integer", "double", "string", "byte array", "boolean array",
               "integer array", "double array", "string array")


def describe_text(descriptor) -> str:
    """One parameter's rcl_interfaces/ParameterDescriptor as `ros2 param describe` prints it."""
    kind = _TYPE_NAMES[descriptor.type] if 0 <= descriptor.type < len(_TYPE_NAMES) else "unknown type"
    lines = [f"Parameter name: {descriptor.name}", f"  Type: {kind}"]
    if descriptor.description:
        lines.append(f"  Description: {descriptor.description}")
    lines.append("  Constraints:")
    if descriptor.read_only:
        lines.append("    Read only: true")
    ranges = list(descriptor.floating_point_range) + list(descriptor.integer_range)
    if ranges:
        lines += [f"    Min value: {ranges[0].from_value}", f"    Max value: {ranges[0].to_value}"]
        if ranges[0].step:
            lines.append(f"    Step: {ranges[0].step}")
    if descriptor.additional_constraints:
        lines.append(f"    Additional constraints: {descriptor.additional_constraints}")
    return "\n".join(lines)


def cmd_describe(args) -> int:
    from rcl_interfaces.srv import DescribeParameters

    node = full_node_name(args.node_name)
    with _open(args) as session:
        response = _service(session, node, "describe_parameters", DescribeParameters,
                            DescribeParameters.Request(names=args.parameter_names))
        descriptors = list(response.descriptors)
        # rclpy answers an undeclared name with no descriptors at all; others with type "not set"
        described = {d.name for d in descriptors if d.type != 0}
        unknown = [name for name in args.parameter_names if name not in described]
        if unknown:
            raise undeclared(session, node, unknown[0], "parameter ")
    print("\n".join(describe_text(d) for d in descriptors))
    return 0


def cmd_list(args) -> int:
    node = full_node_name(args.node_name)
    with _open(args) as session:
        names = list_names(session, node)
    print(f"{node}:")
    for name in names:
        print(f"  {name}")
    return 0


def parameters_from_file(text: str, node: str, path: str = "parameter file") -> Dict[str, Any]:
    """The flat parameters for `node` in a ROS parameter file (its node key or '/**')."""
    from ball_balance.cli.messages import parse_yaml_values

    data = parse_yaml_values(text, what=f"the parameters in {path}")
    if not isinstance(data, dict):
        raise CliError(f"{path}: expected '<node>: {{ros__parameters: {{...}}}}' at the top level")
    params: Dict[str, Any] = {}
    for key in ("/**", node, node.lstrip("/")):
        section = data.get(key)
        if section is None:
            continue
        if not isinstance(section, dict) or not isinstance(section.get("ros__parameters"), dict):
            raise CliError(f"{path}: section '{key}' has no 'ros__parameters' mapping")
        params.update(flatten(section["ros__parameters"]))
    if not params:
        raise CliError(f"{path}: no parameters for node '{node}' (sections: {', '.join(map(str, data))})")
    return params


def read_parameter_file(path: str) -> str:
    """The text of a parameter file a user names; a CliError naming it when it cannot be read
    or is not text (a binary file: no UnicodeDecodeError from deep inside the YAML parser)."""
    try:
        return read_text_file(path, "parameter file")
    except TextFileError as error:
        raise CliError(str(error)) from None


def cmd_load(args) -> int:
    node = full_node_name(args.node_name)
    params = parameters_from_file(read_parameter_file(args.parameter_file), node, args.parameter_file)
    with _open(args) as session:
        results = set_values(session, node, params)
    failed = 0
    for name, result in zip(params, results, strict=True):
        if result.successful:
            print(f"Set parameter {name} successful")
        else:
            failed += 1
            print(f"Set parameter {name} failed: {result.reason or 'refused by the node'}")
    return 1 if failed else 0
