#!/usr/bin/env bash
# Set up the ball_balance workspace: a Python venv with ROS 2 Jazzy (from PyPI wheels, or
# the sourced Jazzy installation), our pinned Python dependencies, the Debian packages
# MuJoCo needs to render offscreen, and a colcon build of our packages into ./install.
#
# Idempotent: each step keeps a stamp of its inputs and is skipped when they are unchanged,
# so a re-run on an up-to-date workspace takes about a second.
#
#   scripts/setup.sh            set up (or bring up to date)
#   scripts/setup.sh --force    redo every step
#   scripts/setup.sh --help     this text (and nothing else)
#   BALL_BALANCE_PYTHON=python3.12 scripts/setup.sh   choose the interpreter (3.11 or 3.12)
#
# Afterwards `source env.sh` gives a shell where our nodes, `ros2py` and pytest work.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
STAMPS="$VENV/.ball_balance_stamps"
FORCE=0
usage() { sed -n '2,/^[^#]/{/^#/p}' "$0" | sed 's/^# \{0,1\}//'; }   # the header comment
for arg; do
  case "$arg" in
    --force) FORCE=1 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "setup.sh: unknown argument '$arg' (see --help)" >&2; exit 2 ;;
  esac
done

# One set-up at a time per checkout (parallel runs would race in colcon's build folder); the
# lock lives in the checkout, so runs with different TMPDIRs still exclude each other.
mkdir -p "$ROOT/build"
exec 9>"$ROOT/build/.setup.lock"
flock 9

say() { printf '\033[1m[setup]\033[0m %s\n' "$*"; }
die() { printf '[setup] error: %s\n' "$*" >&2; exit 1; }
trap 'die "step failed at scripts/setup.sh line $LINENO"' ERR

# --- which ROS: a sourced Jazzy installation, or the PyPI wheels ---------------------
if [[ "${ROS_DISTRO:-}" == "jazzy" && -n "${AMENT_PREFIX_PATH:-}" ]]; then
  MODE=system
  PYTHON=/usr/bin/python3
  ROS_REQUIREMENTS="$ROOT/requirements/ros-system.txt"
elif [[ -n "${ROS_DISTRO:-}" ]]; then
  die "ROS_DISTRO=$ROS_DISTRO is sourced; ball_balance targets Jazzy. Open a shell without it (wheels are used) or source Jazzy."
else
  MODE=wheels
  PYTHON=""
  for candidate in ${BALL_BALANCE_PYTHON:-} python3 python3.12 python3.11; do
    if command -v "$candidate" >/dev/null 2>&1 && "$candidate" 2>/dev/null -c 'import sys; sys.exit(sys.version_info[:2] not in ((3, 11), (3, 12)))'; then
      PYTHON="$("$candidate" -c 'import sys; print(sys.executable)')"; break
    fi
  done
  [[ -n "$PYTHON" ]] || die "needs Python 3.11 or 3.12 (the ROS 2 Jazzy wheels exist only for those)"
  [[ "$(uname -m)" == "x86_64" ]] || die "the ROS 2 Jazzy wheels exist only for x86_64 Linux"
  ROS_REQUIREMENTS="$ROOT/requirements/ros-jazzy-wheels.txt"
fi

# stamp_ok NAME INPUT: true when step NAME already ran with this INPUT (and not --force)
stamp_ok() { [[ $FORCE == 0 && -f "$STAMPS/$1" && "$(cat "$STAMPS/$1")" == "$2" ]]; }
stamp_set() { mkdir -p "$STAMPS"; printf '%s' "$2" >"$STAMPS/$1"; }
digest() { cat "$@" 2>/dev/null | sha256sum | cut -c1-16; }

# --- 1. Debian packages: an OpenGL software renderer for MuJoCo (EGL and OSMesa) ------
APT_PACKAGES=(libegl1 libegl-mesa0 libgl1-mesa-dri libgl1 libosmesa6)
missing=()
for pkg in "${APT_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if ((${#missing[@]})); then
  say "installing Debian packages: ${missing[*]}"
  SUDO=""; [[ $(id -u) == 0 ]] || SUDO="sudo"
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get update -qq
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# --- 2. the venv and the pinned Python packages ---------------------------------------
want="$MODE $($PYTHON -c 'import sys; print(sys.version.split()[0])') $(digest "$ROS_REQUIREMENTS" "$ROOT/requirements/python.txt")"
if ! stamp_ok pip "$want" || [[ ! -x "$VENV/bin/python" ]]; then
  if [[ ! -x "$VENV/bin/python" ]]; then
    say "creating venv ($MODE mode, $PYTHON)"
    if [[ $MODE == system ]]; then
      "$PYTHON" -m venv --system-site-packages "$VENV"
    else
      "$PYTHON" -m venv "$VENV"
    fi
  fi
  say "installing pinned Python packages (about 30 s the first time)"
  "$VENV/bin/python" -m pip install -q --disable-pip-version-check --upgrade pip 2>&1 | grep -v '^WARNING: Location' || true
  "$VENV/bin/python" -m pip install -q --disable-pip-version-check \
      -r "$ROS_REQUIREMENTS" -r "$ROOT/requirements/python.txt" 2>&1 | grep -v '^WARNING: Location' || true
  "$VENV/bin/python" -c 'import mujoco, cv2, numpy, yaml, yourdfpy' \
      || die "Python packages did not install; see the pip output above"
  stamp_set pip "$want"
  rm -f "$STAMPS/build"  # new packages: rebuild our workspace against them
fi

# --- 3. the wheels' include-path pitfall -----------------------------------------------
# The wheels' exported CMake targets for generated Python code name the include folders
# of the machine that built them (/opt/python/cpXY-cpXY/...). Point them at ours once.
if [[ $MODE == wheels ]]; then
  "$VENV/bin/python" "$ROOT/scripts/tools/fix_wheel_cmake_paths.py" "$VENV"
fi

# --- 4. colcon build -----------------------------------------------------------------
# colcon never descends into a package's folder, so the nested interface packages are
# named explicitly. Interface packages a ROS installation already has are not rebuilt.
PACKAGE_PATHS=(. controller_manager_py ball_tracker_msgs)
for pkg in tf2_msgs controller_manager_msgs pal_statistics_msgs control_msgs; do
  provided=0
  if [[ $MODE == system ]]; then
    IFS=: read -ra prefixes <<<"${AMENT_PREFIX_PATH:-}"
    for prefix in "${prefixes[@]}"; do
      [[ "$prefix" == "$ROOT/install" ]] && continue
      [[ -f "$prefix/share/ament_index/resource_index/packages/$pkg" ]] && provided=1
    done
  fi
  if ((provided)); then say "using the installed $pkg"; else PACKAGE_PATHS+=("interfaces/$pkg"); fi
done

build_inputs=$(cd "$ROOT" && find "${PACKAGE_PATHS[@]}" -maxdepth 3 \
    \( -name package.xml -o -name CMakeLists.txt -o -name '*.msg' -o -name '*.srv' -o -name '*.action' -o -name setup.py -o -name setup.cfg \) \
    -not -path './.venv/*' -not -path './build/*' -not -path './install/*' | sort)
want="$MODE ${PACKAGE_PATHS[*]} $(cd "$ROOT" && digest $build_inputs) $(cd "$ROOT" && { find config -type f 2>/dev/null || true; } | sort | digest -)"
if ! stamp_ok build "$want" || [[ ! -f "$ROOT/install/setup.bash" ]]; then
  say "building the workspace with colcon (${PACKAGE_PATHS[*]})"
  mkdir -p "$ROOT/build"
  (
    cd "$ROOT"
    export PATH="$VENV/bin:$PATH"
    if [[ $MODE == wheels ]]; then
      export AMENT_PREFIX_PATH="$VENV"
      export CMAKE_PREFIX_PATH="$VENV"
    fi
    # colcon through the venv's Python, in both modes: our executables get the interpreter
    # that ran colcon. An installation's colcon (#!/usr/bin/python3) would give them the system
    # Python, without the venv's MuJoCo, numpy and OpenCV (the system mode's test caught it).
    "$VENV/bin/python" -c 'import sys; from colcon_core.command import main; sys.argv[0] = "colcon"; sys.exit(main())' \
      --log-base build/log build --merge-install --symlink-install \
      --build-base build --install-base install \
      --paths "${PACKAGE_PATHS[@]}" \
      --event-handlers console_cohesion- summary+ status- \
      --cmake-args -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$VENV/bin/python" \
      >"$ROOT/build/colcon.log" 2>&1 || { tail -n 60 "$ROOT/build/colcon.log" >&2; die "colcon build failed (log: build/colcon.log)"; }
  ) || exit 1
  stamp_set build "$want"
fi

# --- 4b. a `ros2` command (our ros2py) only where no real ROS 2 `ros2` exists ----------
"$ROOT/ball_balance/cli/install_ros2_shim.sh" "$VENV" | sed 's/^/[setup] /'

# --- 4c. kernel socket limits: whole camera frames over UDP ---------------------------
# config/dds asks for 4 MiB socket buffers (docs/transport.md); the kernel silently caps
# them at net.core.rmem_max / wmem_max, and with the usual 208 KiB a 1 MB frame from a
# camera driver on another DDS (or another host) is lost whole over best effort.
DDS_SOCKET_BUFFER_BYTES=4194304
for limit in rmem_max wmem_max; do
  value=$(cat "/proc/sys/net/core/$limit" 2>/dev/null || echo 0)
  if ((value < DDS_SOCKET_BUFFER_BYTES)); then
    say "warning: net.core.$limit is $value bytes; camera frames over UDP need $DDS_SOCKET_BUFFER_BYTES."
    say "  sudo sysctl -w net.core.$limit=$DDS_SOCKET_BUFFER_BYTES   (and persist it in /etc/sysctl.d/, see docs/transport.md)"
  fi
done

# --- 5. env.sh: everything a shell needs to run our nodes ------------------------------
cat >"$ROOT/env.sh" <<EOF
# Generated by scripts/setup.sh ($MODE mode). Source it: . env.sh
export BALL_BALANCE_ROOT="$ROOT"
export VIRTUAL_ENV="$VENV"
export PATH="$ROOT/install/lib/ball_balance:$ROOT/install/lib/controller_manager_py:$VENV/bin:\$PATH"
$( [[ $MODE == wheels ]] && echo "export AMENT_PREFIX_PATH=\"$VENV\${AMENT_PREFIX_PATH:+:\$AMENT_PREFIX_PATH}\"" )
# the ROS setup scripts read unset variables: nounset off while they run, then the caller's again
case \$- in *u*) _bb_nounset=1; set +u;; *) _bb_nounset=0;; esac
source "$ROOT/install/local_setup.bash"
if ((_bb_nounset)); then set -u; fi; unset _bb_nounset
export MUJOCO_GL="\${MUJOCO_GL:-egl}"
export PYOPENGL_PLATFORM="\${PYOPENGL_PLATFORM:-\$MUJOCO_GL}"
# DDS settings for camera frames at full rate (docs/transport.md); your own files win
export FASTRTPS_DEFAULT_PROFILES_FILE="\${FASTRTPS_DEFAULT_PROFILES_FILE:-$ROOT/config/dds/fastdds.xml}"
export FASTDDS_DEFAULT_PROFILES_FILE="\${FASTDDS_DEFAULT_PROFILES_FILE:-\$FASTRTPS_DEFAULT_PROFILES_FILE}"
export CYCLONEDDS_URI="\${CYCLONEDDS_URI:-file://$ROOT/config/dds/cyclonedds.xml}"
EOF
say "ready ($MODE mode): source env.sh, or use scripts/run_demo.sh and scripts/test.sh"
