#!/usr/bin/env bash
# Build a stand-in ROS 2 Jazzy installation at PREFIX, so that the ROS-installation ("system")
# path of scripts/setup.sh can run where no Jazzy is installed (CI):
#
#   PREFIX/setup.bash          sets ROS_DISTRO=jazzy, AMENT_PREFIX_PATH, CMAKE_PREFIX_PATH,
#                              PYTHONPATH, PATH and LD_LIBRARY_PATH as a Jazzy setup.bash does
#   PREFIX/lib/pythonX.Y/site-packages, PREFIX/lib, PREFIX/share, PREFIX/bin
#                              the pinned Jazzy packages of requirements/ros-jazzy-wheels.txt
#                              (rclpy, messages, ament, rosidl, colcon), installed for the
#                              system Python (/usr/bin/python3) as an /opt/ros/jazzy would be
#
# numpy and OpenCV are left out (a Jazzy install takes them from the system; setup.sh's system
# mode pins numpy 1.26 in the workspace venv). Reused when the pins and this script are
# unchanged (a stamp file); about a minute the first time.
#
#   scripts/tools/standin_jazzy.sh /tmp/standin_jazzy
#   source /tmp/standin_jazzy/setup.bash && scripts/setup.sh    # takes the system mode
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
PREFIX="${1:?usage: standin_jazzy.sh PREFIX}"
PYTHON=/usr/bin/python3
WHEELS="$ROOT/requirements/ros-jazzy-wheels.txt"
stamp="$(cat "$WHEELS" "${BASH_SOURCE[0]}" | sha256sum | cut -c1-16) $("$PYTHON" -c 'import sys; print(sys.version.split()[0])')"
if [[ -f "$PREFIX/.standin_stamp" && "$(cat "$PREFIX/.standin_stamp")" == "$stamp" ]]; then
  exit 0
fi
rm -rf "$PREFIX"
mkdir -p "$PREFIX"
PREFIX="$(cd "$PREFIX" && pwd)"
# the ROS packages and build tools of the pins (not numpy, not OpenCV)
sed -e 's/#.*//' -e 's/[[:space:]]*$//' "$WHEELS" | grep -E '^(ros-|catkin-pkg|colcon-)' >"$PREFIX/packages.txt"
echo "standin_jazzy.sh: installing $(wc -l <"$PREFIX/packages.txt") pinned Jazzy packages into $PREFIX" >&2
# pip of a throwaway venv of the system Python: its install scheme puts the wheels' code and
# their data (share/, lib/*.so, generated message code) under one lib/pythonX.Y/site-packages,
# as in /opt/ros/jazzy (Debian's own pip would split them into local/.../dist-packages).
TOOL="$PREFIX/.pip_venv"
"$PYTHON" -m venv "$TOOL"
"$TOOL/bin/python" -m pip install -q --disable-pip-version-check --no-warn-script-location \
  --prefix "$PREFIX" -r "$PREFIX/packages.txt" 2>&1 | grep -v '^WARNING: Location' >&2 || true
rm -rf "$TOOL"
# console scripts (colcon, ...) run with the system Python, as apt's do
for script in "$PREFIX"/bin/*; do
  if [[ -f "$script" ]] && head -c 64 "$script" | grep -q "^#!.*/.pip_venv/bin/python"; then
    sed -i "1s|^#!.*|#!$PYTHON|" "$script"
  fi
done
SITE="$(cd "$PREFIX" && ls -d lib/python3*/site-packages | head -1)"
[[ -d "$PREFIX/$SITE/rclpy" ]] || { echo "standin_jazzy.sh: rclpy did not install into $PREFIX" >&2; exit 1; }
# what the system provides on a real install, not the ROS prefix
rm -rf "$PREFIX/$SITE"/numpy "$PREFIX/$SITE"/numpy-* "$PREFIX/$SITE"/numpy.libs "$PREFIX/bin/f2py" \
  "$PREFIX/bin/numpy-config"

# The wheels' own bundled libraries (ros_*.libs): a wheel-installed Python finds them through a
# re-exec from a .pth file, which is not read on PYTHONPATH. An installation's setup.bash puts
# its library folders on LD_LIBRARY_PATH; so does ours.
rm -f "$PREFIX/$SITE/ros_wheels_bootstrapper.pth"
LIBS="$PREFIX/lib"
for dir in "$PREFIX/$SITE"/ros_*.libs; do [[ -d "$dir" ]] && LIBS="$LIBS:$dir"; done

cat >"$PREFIX/setup.bash" <<EOF
# Stand-in ROS 2 Jazzy installation (scripts/tools/standin_jazzy.sh): source it as /opt/ros/jazzy/setup.bash
export ROS_DISTRO=jazzy
export ROS_VERSION=2
export ROS_PYTHON_VERSION=3
export AMENT_PREFIX_PATH="$PREFIX\${AMENT_PREFIX_PATH:+:\$AMENT_PREFIX_PATH}"
export CMAKE_PREFIX_PATH="$PREFIX\${CMAKE_PREFIX_PATH:+:\$CMAKE_PREFIX_PATH}"
export PYTHONPATH="$PREFIX/$SITE\${PYTHONPATH:+:\$PYTHONPATH}"
export PATH="$PREFIX/bin:\$PATH"
export LD_LIBRARY_PATH="$LIBS\${LD_LIBRARY_PATH:+:\$LD_LIBRARY_PATH}"
EOF
# The wheels' exported CMake targets name their build machine's Python include folders (a
# wheel artifact, not something a Jazzy install has): point them at this machine's.
"$PYTHON" "$ROOT/scripts/tools/fix_wheel_cmake_paths.py" "$PREFIX" >&2
printf '%s' "$stamp" >"$PREFIX/.standin_stamp"
echo "standin_jazzy.sh: ready: source $PREFIX/setup.bash" >&2
