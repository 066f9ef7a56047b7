"""Untrusted command arrays checked at the edge and handed to update() through one slot.

`CommandSlot.offer(values)` runs in the subscription callback (executor thread): a command
of the wrong length or with a non-finite value is refused, counted and logged throttled;
a good one replaces the slot's tuple (one reference assignment: the loop never sees a
half-written command). `take()` in update() returns the latest good command or None.
`reset()` (on activate/deactivate) restores the "no command yet" sentinel.
"""
from __future__ import annotations

import math
from typing import Optional, Sequence, Tuple

from ..manager.throttle import Throttle


class CommandSlot:
    def __init__(self, name: str, size: int, logger):
        self.name, self.size = name, size
        self.throttle = Throttle(logger)
        self.refused = 0
        self._value: Optional[Tuple[float, ...]] = None

    def offer(self, values: Sequence[float]) -> bool:
        if len(values) != self.size:
            return self._refuse("length", f"{self.name}: command has {len(values)} values, "
                                          f"expected {self.size}; ignored")
        command = tuple(float(v) for v in values)
        if not all(math.isfinite(v) for v in command):
            return self._refuse("finite", f"{self.name}: command contains a non-finite value {list(command)}; ignored")
        self._value = command
        return True

    def _refuse(self, key: str, message: str) -> bool:
        self.refused += 1
        self.throttle.warn(key, f"{message} (refused so far: {self.refused})")
        return False

    def take(self) -> Optional[Tuple[float, ...]]:
        return self._value

    def reset(self) -> None:
        self._value = None
