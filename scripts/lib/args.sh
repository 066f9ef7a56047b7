# Sourced by the graph scripts to check their command-line values before anything starts: a
# value that is not what an option takes ends the script with one line and exit code 2,
# instead of a graph that starts and then stops (or, for a negative --duration, never ends).

# check_node_params EXE ROS_ARGS...: EXE built with `--ros-args ROS_ARGS...` and its parameters
# checked, without spinning and unseen by any other participant (node_main's --check-params);
# 0, or the node's one line and 2. At normal priority: only the check runs.
check_node_params() {
  local exe="$1"; shift
  env -u ROS_LOCALHOST_ONLY ROS_AUTOMATIC_DISCOVERY_RANGE=OFF "$exe" --check-params --ros-args "$@" \
    -p thread_priority:=0
}

# require_ros_domain SCRIPT: ROS_DOMAIN_ID (0 when unset) is one DDS can use: DDS derives its
# ports from it, and past 232 they do not exist (each process would print a transport error)
require_ros_domain() {
  local id="${ROS_DOMAIN_ID:-0}"
  [[ "$id" =~ ^[0-9]+$ ]] && ((10#$id <= 232)) && return 0
  echo "$1: ROS_DOMAIN_ID=$id is not a ROS domain: take 0-232 (0-101 keep clear of Linux's" \
    "ephemeral ports)" >&2
  exit 2
}

# require_number SCRIPT OPTION VALUE: VALUE is a plain number >= 0 (12, 0.5, .5, 1e-3)
require_number() {
  [[ "$3" =~ ^([0-9]+[.]?[0-9]*|[.][0-9]+)([eE][-+]?[0-9]+)?$ ]] \
    || { echo "$1: $2 takes a number >= 0, got '$3'" >&2; exit 2; }
}

# require_size SCRIPT OPTION VALUE: VALUE is a camera image size WIDTHxHEIGHT (640x480)
require_size() {
  [[ "$3" =~ ^[1-9][0-9]*x[1-9][0-9]*$ ]] || { echo "$1: $2 '$3' must be WIDTHxHEIGHT" >&2; exit 2; }
}

# needs COUNT OPTION ARGS...: OPTION (the option being parsed, "$@" of the option loop) has its
# COUNT values after it; else one line and exit 2 (an option given last without its value ended
# the script on bash's `$2: unbound variable`). A value cannot start with `--`: that is the next
# option (a negative number, -0.05, is a value).
needs() {
  local count="$1" option="$2" i
  shift 2
  for ((i = 1; i <= count; i++)); do
    if ((i > $#)) || [[ "${!i}" == --* ]]; then
      local what="a value"
      ((count == 1)) || what="$count values"
      echo "$(basename "$0"): $option needs $what (see --help)" >&2
      exit 2
    fi
  done
}

# require_port SCRIPT OPTION VALUE: VALUE is a TCP port, 1-65535 (or 0: a free one, chosen at start)
require_port() {
  [[ "$3" =~ ^(0|[1-9][0-9]{0,4})$ ]] && (($3 <= 65535)) && return 0
  echo "$1: $2 takes a port number 1-65535 (0: a free one), got '$3'" >&2
  exit 2
}

# require_out_dir SCRIPT OPTION DIR: DIR made (mkdir -p) and writable, before anything starts
# (the results are written there at the end of a run: a run must not be lost to a bad folder)
require_out_dir() {
  local why
  if ! why="$(mkdir -p -- "$3" 2>&1)"; then
    echo "$1: $2 '$3': cannot create the folder: ${why##*: }" >&2
    exit 2
  fi
  [[ -w "$3" && -x "$3" ]] || { echo "$1: $2 '$3': the folder is not writable" >&2; exit 2; }
}

# require_params_file SCRIPT OPTION FILE: FILE is a ROS parameter file (a YAML mapping of node
# names) that can be read; else the checker's line (naming the file and the problem) and exit 2
require_params_file() {
  python -c 'import sys
from controller_manager_py.ros.params_files import ParamsFileError, check_params_file
try:
    check_params_file(sys.argv[3])
except ParamsFileError as error:
    sys.exit(f"{sys.argv[1]}: {sys.argv[2]}: {error}")' "$@" || exit 2
}
