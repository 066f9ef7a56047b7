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
