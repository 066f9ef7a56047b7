"""ROS parameter files (`--ros-args --params-file FILE`): read and checked before rcl sees them.

rcl reports a missing or malformed parameter file with its own error line (and the C
source location) and the node then adds another; checking the files first gives one line
naming the file and the problem. Used by every node's main (node_main.py, next to this file)
and by command-line tools that start nodes. No rclpy import: the check runs before rclpy is
initialised.
"""
from __future__ import annotations

from typing import Any, List

from ..text_files import TextFileError, read_text_file


class ParamsFileError(ValueError):
    """A parameter file cannot be read or is not a ROS parameter file (one-line message)."""


def load_yaml_text(text: str, what: str) -> Any:
    """YAML text -> Python value; a ParamsFileError with the parser's first line when malformed.

    `what` names the text in the message: "{what} are not valid YAML: ... at line L, column C".
    """
    import yaml

    try:
        return yaml.safe_load(text) if text.strip() else {}
    except yaml.YAMLError as error:
        problem = getattr(error, "problem", None) or str(error).splitlines()[0]
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        context = getattr(error, "context", None)
        raise ParamsFileError(f"{what} are not valid YAML: {problem}{where}"
                              + (f" ({context})" if context else "")) from None


def params_files_in(argv: List[str]) -> List[str]:
    """The paths given with `--params-file` inside `--ros-args ... [--]` sections of argv."""
    paths, in_ros_args = [], False
    for i, arg in enumerate(argv):
        if arg == "--ros-args":
            in_ros_args = True
        elif arg == "--":
            in_ros_args = False
        elif in_ros_args and arg == "--params-file" and i + 1 < len(argv):
            paths.append(argv[i + 1])
    return paths


def check_params_file(path: str) -> dict:
    """Read one parameter file: its top-level mapping, or ParamsFileError naming the file."""
    try:
        text = read_text_file(path, "parameter file")
    except TextFileError as error:
        raise ParamsFileError(str(error)) from None
    data = load_yaml_text(text, what=f"the parameters in '{path}'")
    if not isinstance(data, dict):
        raise ParamsFileError(f"parameter file '{path}' must map node names to {{ros__parameters: {{...}}}}")
    return data


def check_params_files(argv: List[str]) -> None:
    """Refuse a missing or malformed `--params-file` of argv with one line (ParamsFileError)."""
    for path in params_files_in(argv):
        check_params_file(path)
