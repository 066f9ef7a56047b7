#!/usr/bin/env python3
"""Write docs/parameters.md from the parameter schemas (controller_manager_py.parameters.Param).

One section per component (a node, the controller manager, a hardware or controller plugin):
its node or plugin name, the file that declares it, the files its parameters are defined in,
and a table (name, default, unit, range, description) in the schema's order, which is the
order the component declares them. The schemas are imported, no ROS node is started.

    python scripts/gen_param_docs.py            # (re)write docs/parameters.md
    python scripts/gen_param_docs.py --check    # exit 1 when docs/parameters.md is stale

Every executable and plugin of both setup.py files (the root one and controller_manager_py's)
must be listed in COMPONENTS or in WITHOUT_SCHEMA (else this script fails): a new node or
plugin cannot be left out of the file unnoticed.
test/unit/test_parameter_docs.py runs the check.
"""
from __future__ import annotations

import argparse
import ast
import importlib
import inspect
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple

ROOT = Path(__file__).resolve().parents[1]
for _folder in (ROOT, ROOT / "controller_manager_py"):  # ball_balance, and controller_manager_py's package folder
    if str(_folder) not in sys.path:
        sys.path.insert(0, str(_folder))  # document the working tree, not an installed copy

from controller_manager_py.parameters import Param  # noqa: E402

OUTPUT = ROOT / "docs" / "parameters.md"
COMMAND = "python scripts/gen_param_docs.py"
JOINT = "<joint>"  # stands for each joint of a trajectory controller's `joints`


@dataclass(frozen=True)
class Component:
    kind: str           # "node", "hardware plugin" or "controller plugin"
    name: str           # node name or plugin string
    target: str         # "module:attribute" of the node class / module, or of the plugin class
    schema: Callable[[], Sequence[Param]]
    executable: str = ""  # `ros2 run <package> <executable>` for a node
    package: str = "ball_balance"


def _attr(target: str):
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)


def _module_schema(module: str, attr: str = "SCHEMA") -> Callable[[], Sequence[Param]]:
    return lambda: list(getattr(importlib.import_module(module), attr))


def _balance_node_schema(target: str) -> Callable[[], Sequence[Param]]:
    """A balance node declares its controller's SCHEMA, then balance_node_base.NODE_SCHEMA."""
    def schema():
        base = importlib.import_module("ball_balance.nodes.balance_node_base")
        return [*_attr(target).SCHEMA, *base.NODE_SCHEMA]
    return schema


def _controller_schema(target: str) -> Callable[[], Sequence[Param]]:
    """A controller's param_schema() (COMMON_PARAMS first); per-joint parameters for JOINT."""
    def schema():
        controller = _attr(target)()
        controller.load_params({"joints": [JOINT]})
        return controller.param_schema()
    return schema


def _hardware_schema(target: str) -> Callable[[], Sequence[Param]]:
    module = target.partition(":")[0]
    return _module_schema(module)


NODES = [
    ("ball_tracker", "ball_tracker", "ball_balance.nodes.ball_tracker_node:BallTrackerNode",
     _module_schema("ball_balance.nodes.ball_tracker_node")),
    ("ball_balance_controller", "ball_balance_controller", "ball_balance.nodes.pid_controller_node:PidControllerNode",
     _balance_node_schema("ball_balance.nodes.pid_controller_node:PidControllerNode")),
    ("ball_balance_mpc", "ball_balance_mpc", "ball_balance.nodes.mpc_controller_node:MpcControllerNode",
     _balance_node_schema("ball_balance.nodes.mpc_controller_node:MpcControllerNode")),
    ("ball_balance_policy", "ball_balance_policy", "ball_balance.nodes.policy_node:PolicyControllerNode",
     _balance_node_schema("ball_balance.nodes.policy_node:PolicyControllerNode")),
    ("ball_balance_visualizer", "ball_balance_visualizer", "ball_balance.nodes.visualizer_node:VisualizerNode",
     _module_schema("ball_balance.nodes.visualizer_node")),
    ("ball_balance_foxglove", "ball_balance_foxglove", "ball_balance.nodes.foxglove_node:FoxgloveNode",
     _module_schema("ball_balance.nodes.foxglove_node")),
    ("ball_balance_live_view", "ball_balance_live_view", "ball_balance.nodes.live_view_node:LiveViewNode",
     _module_schema("ball_balance.nodes.live_view_node")),
    ("robot_state_publisher", "robot_state_publisher",
     "ball_balance.nodes.robot_state_publisher_node:RobotStatePublisherNode",
     _module_schema("ball_balance.nodes.robot_state_publisher_node")),
    ("robot_manager", "robot_manager", "ball_balance.nodes.robot_manager_node:RobotManagerNode",
     _module_schema("ball_balance.nodes.robot_manager_node")),
    ("ros2_control_node", "controller_manager", "controller_manager_py.ros.node:ControllerManagerNode",
     _module_schema("controller_manager_py.ros.node")),
    ("camera_snapshot", "camera_snapshot", "ball_balance.nodes.camera_snapshot_node:CameraSnapshotNode",
     _module_schema("ball_balance.nodes.camera_snapshot_node")),
]

# executables and plugins of setup.py that declare no Param schema
WITHOUT_SCHEMA = {
    "ros2py": "command-line tool",
    "spawner": "command-line tool (its options are arguments, not parameters)",
    "mock_components/GenericSystem": "hardware parameters are read from the URDF as upstream's, without a schema",
}


# the two packages' setup.py files: (package, path, {its dict name: the merged name})
SETUPS = (
    ("controller_manager_py", ROOT / "controller_manager_py" / "setup.py",
     {"EXECUTABLES": "EXECUTABLES", "HARDWARE": "CMPY_HARDWARE", "CONTROLLERS": "CMPY_CONTROLLERS"}),
    ("ball_balance", ROOT / "setup.py",
     {"EXECUTABLES": "EXECUTABLES", "CMPY_HARDWARE": "CMPY_HARDWARE", "CMPY_CONTROLLERS": "CMPY_CONTROLLERS"}),
)


def _setup_dicts() -> Dict[str, Dict[str, str]]:
    """EXECUTABLES, CMPY_HARDWARE and CMPY_CONTROLLERS of both setup.py files (read, not run),
    controller_manager_py's first; PACKAGES maps each executable to its package."""
    found: Dict[str, Dict[str, str]] = {"EXECUTABLES": {}, "CMPY_HARDWARE": {}, "CMPY_CONTROLLERS": {},
                                        "PACKAGES": {}}
    for package, path, names in SETUPS:
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
                name = node.targets[0].id
                if name in names:
                    values = ast.literal_eval(node.value)
                    found[names[name]].update(values)
                    if name == "EXECUTABLES":
                        found["PACKAGES"].update({executable: package for executable in values})
    return found


def components() -> List[Component]:
    """Every documented component, in the file's order: nodes, hardware plugins, controller plugins."""
    setup = _setup_dicts()
    result = []
    for executable, name, target, schema in NODES:
        if executable not in setup["EXECUTABLES"]:
            raise SystemExit(f"gen_param_docs: no executable '{executable}' in setup.py (NODES is stale)")
        result.append(Component("node", name, target, schema, executable, setup["PACKAGES"][executable]))
    for plugin, target in setup["CMPY_HARDWARE"].items():
        if plugin not in WITHOUT_SCHEMA:
            result.append(Component("hardware plugin", plugin, target, _hardware_schema(target)))
    for plugin, target in setup["CMPY_CONTROLLERS"].items():
        if plugin not in WITHOUT_SCHEMA:
            result.append(Component("controller plugin", plugin, target, _controller_schema(target)))
    documented = {n[0] for n in NODES} | set(WITHOUT_SCHEMA)
    missing = [e for e in setup["EXECUTABLES"] if e not in documented]
    if missing:
        raise SystemExit(f"gen_param_docs: executable(s) {', '.join(missing)} of setup.py are neither in NODES "
                         "nor in WITHOUT_SCHEMA (scripts/gen_param_docs.py)")
    return result


# ---- where a parameter is defined ----------------------------------------------------------
# modules holding shared schemas, scanned before the components' own modules so that a
# Param is credited to the module that creates it, not to one that imports or reuses it
SHARED_MODULES = (
    "controller_manager_py.parameters",
    "controller_manager_py.controller_interface.base",
    "controller_manager_py.manager.diagnostics",
    "ball_balance.vision.config",
    "ball_balance.control.config",
    "ball_balance.policy.params",      # after control.config: its POLICY_SCHEMA takes in the PID's
    "ball_balance.nodes.balance_node_base",
)


def _relative(path: str) -> str:
    resolved = Path(path).resolve()
    try:
        return resolved.relative_to(ROOT).as_posix()
    except ValueError:
        return resolved.as_posix()


def _module_file(module) -> str:
    return _relative(inspect.getsourcefile(module))


def _assigned_names(module) -> set:
    """The names a module assigns at its top level (not those it imports)."""
    names = set()
    for node in ast.parse(Path(inspect.getsourcefile(module)).read_text()).body:
        targets = node.targets if isinstance(node, ast.Assign) else \
            [node.target] if isinstance(node, ast.AnnAssign) else []
        names |= {t.id for t in targets if isinstance(t, ast.Name)}
    return names


def _params_in(value) -> List[Param]:
    if isinstance(value, Param):
        return [value]
    if isinstance(value, (list, tuple)) and value and all(isinstance(v, Param) for v in value):
        return list(value)
    return []


def _definitions(comps: Sequence[Component]) -> Tuple[Dict[int, str], Dict[str, str]]:
    """id(Param) -> file defining it (module-level schemas and classes' PARAMS), and name ->
    file for the parameters made per joint by a function (the trajectory tolerances)."""
    by_id: Dict[int, str] = {}
    modules = [importlib.import_module(m) for m in SHARED_MODULES]
    modules += [importlib.import_module(c.target.partition(":")[0]) for c in comps]
    for module in modules:
        where = _module_file(module)
        assigned = _assigned_names(module)
        values = [v for k, v in vars(module).items() if k in assigned]
        values += [getattr(v, "PARAMS", ()) for v in vars(module).values()
                   if inspect.isclass(v) and v.__module__ == module.__name__]
        for value in values:
            for p in _params_in(value):
                by_id.setdefault(id(p), where)
    tolerances = importlib.import_module("controller_manager_py.controllers.tolerances")
    by_name = {p.name: _module_file(tolerances) for p in tolerances.constraint_params([JOINT])}
    return by_id, by_name


# ---- Markdown --------------------------------------------------------------------------------
def _value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    return repr(value)


def _code(text: str) -> str:
    text = text.replace("|", "\\|")
    return f"`` {text} ``" if "`" in text else f"`{text}`"


def _text(text: str) -> str:
    text = text.replace("\\", "\\\\").replace("*", "\\*").replace("|", "\\|")
    return text.replace("<", "&lt;").replace(">", "&gt;").replace("\n", " ")


def _range(p: Param) -> str:
    if p.choices is not None:
        return "one of " + ", ".join(_code(_value(c)) for c in p.choices)
    if p.min is not None and p.max is not None:
        return f"[{_value(p.min)}, {_value(p.max)}]"
    if p.min is not None:
        return f"≥ {_value(p.min)}"
    if p.max is not None:
        return f"≤ {_value(p.max)}"
    return ""


def _anchor(component: Component) -> str:
    return "".join(c if c.isalnum() else "-" for c in f"{component.kind} {component.name}".lower())


def _section(component: Component, params: Sequence[Param], by_id: Dict[int, str],
             by_name: Dict[str, str]) -> List[str]:
    declared_in = _module_file(importlib.import_module(component.target.partition(":")[0]))
    cls = component.target.partition(":")[2]
    counts: Dict[str, int] = {}
    for p in params:
        where = by_id.get(id(p)) or by_name.get(p.name) or declared_in
        counts[where] = counts.get(where, 0) + 1
    lines = [f'<a id="{_anchor(component)}"></a>', f"## {component.kind.capitalize()} `{component.name}`", ""]
    if component.kind == "node":
        lines.append(f"`ros2 run {component.package} {component.executable}`; declared by `{cls}` in `{declared_in}`.")
    elif component.kind == "hardware plugin":
        lines.append(f"Class `{cls}` in `{declared_in}`; set as `<param name=...>` in the URDF's `<hardware>` "
                     "tag, not as ROS parameters.")
    else:
        lines.append(f"Class `{cls}` in `{declared_in}`; set in the controller's section of the manager's "
                     "parameter file.")
    lines.append("Parameters defined in " + ", ".join(f"`{f}` ({n})" for f, n in counts.items()) + ".")
    if any(JOINT in p.name for p in params):
        lines.append(f"`{JOINT}` stands for each joint listed in `joints`.")
    user = [p for p in params if p.user_facing]
    groups = [("User-facing:", user), ("Advanced:", [p for p in params if not p.user_facing])] if user \
        else [("", params)]
    for title, group in groups:
        lines += ["", title, ""] if title else [""]
        lines += ["| name | default | unit | range | description |", "|---|---|---|---|---|"]
        for p in group:
            name = _code(p.name) + (" (read-only)" if p.read_only else "")
            lines.append(f"| {name} | {_code(_value(p.default))} | {_text(p.unit)} | {_range(p)} | "
                         f"{_text(p.description)} |")
    lines.append("")
    return lines


def render() -> str:
    """The whole of docs/parameters.md."""
    comps = components()
    schemas = []
    for component in comps:
        params = list(component.schema())
        names = [p.name for p in params]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise SystemExit(f"gen_param_docs: {component.name} declares {', '.join(duplicates)} twice")
        schemas.append(params)
    by_id, by_name = _definitions(comps)
    lines = [
        "# Parameters",
        "",
        f"_Generated from the parameter schemas by `{COMMAND}`; do not edit by hand. "
        f"`{COMMAND} --check` (run by test/unit/test_parameter_docs.py) fails when this file is stale._",
        "",
        "Each component declares its parameters from a schema of `controller_manager_py.parameters.Param` "
        "(name, default, unit, bounds, description), in the order below. `ros2 param describe` shows the same "
        "descriptions (with the unit and range); a value out of range or of the wrong type stops the component "
        "at start-up with one line naming the parameter. A read-only parameter is set at start-up only "
        "(parameter file or `-p`). Besides these, every node above (run by "
        "`controller_manager_py.ros.node_main`) and the node of every controller declare "
        "`unknown_parameters` (last section), and rclpy declares "
        "`use_sim_time`.",
        "",
        "Each section lists the user-facing parameters first: those a user sets for their own camera, "
        "plate, robot or task. The advanced ones have defaults that suit every setup the project "
        "tests; change them to tune or to investigate.",
        "",
        "| component | kind | user-facing | all |",
        "|---|---|---|---|",
    ]
    for component, params in zip(comps, schemas):
        user = sum(p.user_facing for p in params)
        lines.append(f"| [`{component.name}`](#{_anchor(component)}) | {component.kind} | {user} | {len(params)} |")
    lines.append("")
    for component, params in zip(comps, schemas):
        lines += _section(component, params, by_id, by_name)
    parameters = importlib.import_module("controller_manager_py.parameters")
    lines += [
        "## Every node: `unknown_parameters`",
        "",
        f"Declared by `report_unknown_parameters` in `{_module_file(parameters)}` once a node has declared "
        "its schema, unless the node declares it itself.",
        "",
        "| name | default | unit | range | description |",
        "|---|---|---|---|---|",
    ]
    p = parameters.UNKNOWN_PARAMETERS
    lines.append(f"| {_code(p.name)}{' (read-only)' if p.read_only else ''} | {_code(_value(p.default))} | "
                 f"{_text(p.unit)} | {_range(p)} | {_text(p.description)} |")
    return "\n".join(lines) + "\n"


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 when the file differs from what would be written")
    parser.add_argument("--output", type=Path, default=OUTPUT, help=f"file to write (default {_relative(OUTPUT)})")
    args = parser.parse_args(argv)
    text = render()
    shown = _relative(str(args.output))
    if args.check:
        current = args.output.read_text() if args.output.exists() else None
        if current != text:
            state = "missing" if current is None else "stale"
            print(f"{shown} is {state}: regenerate it with `{COMMAND}`", file=sys.stderr)
            return 1
        return 0
    args.output.write_text(text)
    print(f"wrote {shown}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
