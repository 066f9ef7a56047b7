"""Interface handles: one named float shared by a component, the manager and controllers.

A handle is `<prefix>/<interface>` (e.g. `elbow_joint/position`). Reads and writes are a
plain attribute access (`handle.value`), so the real-time loop touches no dict and
allocates nothing. Controllers receive the same objects as "loaned" interfaces.
"""
from __future__ import annotations

import math

NO_COMMAND = float("nan")
"""The "no command yet" sentinel: a command interface holds NaN until someone writes it."""


class Handle:
    """A named value. `value` is the current float; `get_value()`/`set_value()` are aliases."""

    __slots__ = ("prefix_name", "interface_name", "name", "value", "owner")

    def __init__(self, prefix_name: str, interface_name: str, value: float = NO_COMMAND, owner: str = ""):
        self.prefix_name = prefix_name
        self.interface_name = interface_name
        self.name = f"{prefix_name}/{interface_name}"
        self.value = value
        self.owner = owner  # the hardware component or controller that exports it

    def get_value(self) -> float:
        return self.value

    def set_value(self, value: float) -> bool:
        self.value = value
        return True

    def get_name(self) -> str:
        return self.name

    def __repr__(self) -> str:
        return f"Handle({self.name}={self.value})"


class StateInterface(Handle):
    """A value a component (or a chainable controller) publishes to the system."""

    __slots__ = ()


class CommandInterface(Handle):
    """A value a controller writes and a component (or chained controller) reads.

    `is_limited` is set by the joint-limits stage when it had to change the last command.
    """

    __slots__ = ("is_limited",)

    def __init__(self, prefix_name: str, interface_name: str, value: float = NO_COMMAND, owner: str = ""):
        super().__init__(prefix_name, interface_name, value, owner)
        self.is_limited = False


def is_valid(value: float) -> bool:
    """True for a finite float (commands that may reach hardware)."""
    return math.isfinite(value)
