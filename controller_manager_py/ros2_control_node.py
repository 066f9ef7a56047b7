"""`ros2_control_node` (issue #3)."""
import sys


def main(args=None):
    print("ros2_control_node: not implemented yet (tracked in issue #3).", file=sys.stderr)
    sys.exit(2)
