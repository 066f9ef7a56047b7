"""The exception types the CLI turns into a single `ros2py: <message>` line."""


class CliError(Exception):
    """A user-facing failure: the message is printed as one line and the exit code is 1."""

    exit_code = 1


class BadArgument(CliError):
    """An argument that cannot be used as given (an invalid name): one line, exit code 2, as
    argparse's refusals."""

    exit_code = 2
