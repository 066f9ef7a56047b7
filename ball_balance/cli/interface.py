"""`ros2py interface show TYPE`: the .msg/.srv text with nested types expanded, as ros2 prints it."""
from __future__ import annotations

import os
from typing import List

from ball_balance.cli.bag_format import msg_file_text, nested_type_of
from ball_balance.cli.errors import CliError
from ball_balance.cli.messages import split_type_name
from ball_balance.cli.run import prefixes


def expand(text: str, package: str, indent: str = "") -> List[str]:
    lines = []
    for line in text.splitlines():
        if indent and not line.strip():
            continue
        lines.append(f"{indent}{line}" if line else line)
        nested = nested_type_of(line, package)
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
