"""Point the ROS wheels' exported CMake targets at this machine's Python include folders.

The ros-python-wheels packages export targets for their generated Python code whose
INTERFACE_INCLUDE_DIRECTORIES name the wheel build machine's folders
(/opt/python/cpXY-cpXY/include/pythonX.Y and its numpy include). CMake refuses imported
targets with non-existent include paths, so any interface package that depends on
another package's messages fails to configure. Rewriting them once after install fixes it.
Idempotent: files already pointing at existing folders are left alone.

usage: python fix_wheel_cmake_paths.py PREFIX   (a venv, or a stand-in installation's prefix)

Without numpy importable (a system Python whose numpy comes later, in the workspace venv),
only the Python include folder is named.
"""
import pathlib
import re
import sys
import sysconfig

INCLUDES = re.compile(r'INTERFACE_INCLUDE_DIRECTORIES "([^"]*/opt/python/[^"]*)"')


def main() -> int:
    venv = pathlib.Path(sys.argv[1])
    folders = [sysconfig.get_paths()["include"]]
    try:
        import numpy

        folders.append(numpy.get_include())
    except ImportError:
        pass
    ours = f'INTERFACE_INCLUDE_DIRECTORIES "{";".join(folders)}"'
    fixed = 0
    for path in (venv / "share").glob("*/cmake/*Export.cmake"):
        text = path.read_text()
        if "/opt/python/" not in text:
            continue
        path.write_text(INCLUDES.sub(ours, text))
        fixed += 1
    if fixed:
        print(f"[setup] pointed {fixed} wheel CMake export files at this machine's Python includes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
