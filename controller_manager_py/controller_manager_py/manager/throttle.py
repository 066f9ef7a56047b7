"""Throttled logging for the real-time path: at most one line per key per interval.

The line carries how many occurrences were suppressed since the last one, so nothing is
hidden, and the loop does not spend its budget formatting text.
"""
from __future__ import annotations

import time
from typing import Dict, List


class Throttle:
    def __init__(self, logger, interval_s: float = 2.0):
        self.logger, self.interval_s = logger, interval_s
        self._last: Dict[str, float] = {}
        self._suppressed: Dict[str, int] = {}

    def due(self, key: str) -> bool:
        """True when a line for `key` may be logged now (else the occurrence is counted)."""
        now = time.monotonic()
        last = self._last.get(key)
        if last is not None and now - last < self.interval_s:
            self._suppressed[key] = self._suppressed.get(key, 0) + 1
            return False
        self._last[key] = now
        return True

    def suffix(self, key: str) -> str:
        """' (N more since the last report)' for `key` (empty when none), and restart its count;
        for callers that format their line only when `due()`."""
        n = self._suppressed.pop(key, 0)
        return f" ({n} more since the last report)" if n else ""

    def warn(self, key: str, message: str) -> None:
        if self.due(key):
            self.logger.warning(message + self.suffix(key))

    def error(self, key: str, message: str) -> None:
        if self.due(key):
            self.logger.error(message + self.suffix(key))


def names_of(handles) -> List[str]:
    return [h.name for h in handles]
