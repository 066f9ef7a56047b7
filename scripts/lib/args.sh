# Sourced by the graph scripts to check their command-line values before anything starts: a
# value that is not what an option takes ends the script with one line and exit code 2,
# instead of a graph that starts and then stops (or, for a negative --duration, never ends).

# require_number SCRIPT OPTION VALUE: VALUE is a plain number >= 0 (12, 0.5, .5, 1e-3)
require_number() {
  [[ "$3" =~ ^([0-9]+[.]?[0-9]*|[.][0-9]+)([eE][-+]?[0-9]+)?$ ]] \
    || { echo "$1: $2 takes a number >= 0, got '$3'" >&2; exit 2; }
}
