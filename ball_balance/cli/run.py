"""`ros2py run PACKAGE EXECUTABLE [args]`: exec <prefix>/lib/<package>/<executable>."""
from __future__ import annotations

import os
from typing import List, Optional

from ball_balance.cli.errors import CliError


def prefixes() -> List[str]:
    return [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]


def package_prefix(package: str) -> Optional[str]:
    """The first install prefix that registers `package` in its ament index."""
    for prefix in prefixes():
        if os.path.isfile(os.path.join(prefix, "share", "ament_index", "resource_index", "packages", package)):
            return prefix
    return None


def find_executable(package: str, executable: str) -> str:
    prefix = package_prefix(package)
    if prefix is None:
        raise CliError(f"Package '{package}' not found (AMENT_PREFIX_PATH: "
                       f"{os.environ.get('AMENT_PREFIX_PATH') or 'unset; source env.sh'})")
    lib = os.path.join(prefix, "lib", package)
    path = os.path.join(lib, executable)
    if not (os.path.isfile(path) and os.access(path, os.X_OK)):
        available = sorted(f for f in os.listdir(lib) if os.access(os.path.join(lib, f), os.X_OK)) \
            if os.path.isdir(lib) else []
        raise CliError(f"No executable '{executable}' found in package '{package}' "
                       f"(available: {', '.join(available) or 'none'})")
    return path


def check_params_files(argv: List[str]) -> None:
    """Refuse a missing or malformed `--params-file` with one line before the node starts
    (rcl would log its own error line and the node another)."""
    from ball_balance.cli.messages import parse_yaml_values

    in_ros_args = False
    for i, arg in enumerate(argv):
        if arg == "--ros-args":
            in_ros_args = True
        elif arg == "--":
            in_ros_args = False
        elif in_ros_args and arg == "--params-file" and i + 1 < len(argv):
            path = argv[i + 1]
            try:
                with open(path, encoding="utf-8") as handle:
                    text = handle.read()
            except OSError as error:
                raise CliError(f"cannot read parameter file '{path}': {error.strerror}") from None
            data = parse_yaml_values(text, what=f"the parameters in '{path}'")
            if not isinstance(data, dict):
                raise CliError(f"parameter file '{path}' must map node names to "
                               "{ros__parameters: {...}}")


def cmd_run(args) -> int:
    path = find_executable(args.package_name, args.executable_name)
    argv = list(args.argv)
    if argv[:1] == ["--"]:
        argv = argv[1:]
    check_params_files(argv)
    os.execv(path, [path, *argv])
    return 0  # not reached
