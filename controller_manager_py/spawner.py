"""`spawner` (issue #3)."""
import sys


def main(args=None):
    print("spawner: not implemented yet (tracked in issue #3).", file=sys.stderr)
    sys.exit(2)
