"""The one exception type the CLI turns into a single `ros2py: <message>` line."""


class CliError(Exception):
    """A user-facing failure: the message is printed as one line and the exit code is 1."""
