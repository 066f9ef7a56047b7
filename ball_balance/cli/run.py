"""`ros2py run PACKAGE EXECUTABLE [args]`: exec <prefix>/lib/<package>/<executable>."""
from __future__ import annotations

import os
from typing import List, Optional

from ball_balance.cli.errors import CliError
from ball_balance.cli.param import read_parameter_file
from controller_manager_py.ros.params_files import ParamsFileError, check_params_files, params_files_in


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


def cmd_run(args) -> int:
    path = find_executable(args.package_name, args.executable_name)
    argv = list(args.argv)
    if argv[:1] == ["--"]:
        argv = argv[1:]
    for params_file in params_files_in(argv):  # missing, unreadable or binary: one line naming it
        read_parameter_file(params_file)
    try:  # malformed: one line naming the file, before rcl would log its own
        check_params_files(argv)
    except ParamsFileError as error:
        raise CliError(str(error)) from None
    os.execv(path, [path, *argv])
    return 0  # not reached
