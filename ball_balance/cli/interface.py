"""`ros2py interface show TYPE`: the .msg/.srv text with nested types expanded, as ros2 prints it."""
from __future__ import annotations

import os
import re
from typing import List

from ball_balance.cli.bag import PRIMITIVES, msg_file_text
from ball_balance.cli.errors import CliError
from ball_balance.cli.messages import split_type_name
from ball_balance.cli.run import prefixes


def _nested_type(line: str, package: str):
    """'pkg/Type' for a field line of a non-primitive type, else None."""
    code = line.split("#", 1)[0].strip()
    if not code or re.match(r"\S+\s+\w+\s*=", code) or code == "---":
        return None
    base = code.split()[0].split("[", 1)[0].split("<=", 1)[0]
    if base in PRIMITIVES:
        return None
    if "/" in base:
        parts = base.split("/")
        return f"{parts[0]}/{parts[-1]}"
    return "std_msgs/Header" if base == "Header" else f"{package}/{base}"


def expand(text: str, package: str, indent: str = "") -> List[str]:
    lines = []
    for line in text.splitlines():
        if indent and not line.strip():
            continue
        lines.append(f"{indent}{line}" if line else line)
        nested = _nested_type(line, package)
        if nested:
            nested_package, nested_name = nested.split("/")
            lines.extend(expand(msg_file_text(nested_package, nested_name), nested_package, indent + "\t"))
    return lines


def interface_text(type_name: str) -> str:
    package, kind, name = split_type_name(type_name)
    if kind == "msg":
        return "\n".join(expand(msg_file_text(package, name), package))
    for prefix in prefixes():
        path = os.path.join(prefix, "share", package, kind, f"{name}.{kind}")
        if os.path.isfile(path):
            with open(path, encoding="utf-8") as handle:
                return "\n".join(expand(handle.read(), package))
    raise CliError(f"unknown interface '{type_name}' (no {name}.{kind} in AMENT_PREFIX_PATH)")


def cmd_show(args) -> int:
    print(interface_text(args.type_name))
    return 0
