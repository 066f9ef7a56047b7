"""Placeholder for executables whose issue has not landed yet: says so and exits non-zero."""
import sys


def exit_not_implemented(executable: str, issue: int) -> None:
    print(f"{executable}: not implemented yet (tracked in issue #{issue}).", file=sys.stderr)
    sys.exit(2)
