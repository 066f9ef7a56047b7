"""Keep-last-1 hand-over between a producer (a subscription callback, a render loop) and the
thread that does the work: the worker always gets the newest item, never a queue of old ones.

`LatestSlot.put(item)` never blocks; an item not yet taken is replaced and counted as
`replaced` (a stale frame skipped). `take(timeout_s)` blocks until an item is there (or the
timeout passes, or `close()` was called) and returns it, else None. No ROS.
"""
from __future__ import annotations

import threading
from typing import Generic, Optional, TypeVar

T = TypeVar("T")


class LatestSlot(Generic[T]):
    def __init__(self):
        self._item: Optional[T] = None
        self._cond = threading.Condition()
        self._closed = False
        self.put_count = 0          # items offered
        self.replaced = 0           # items replaced before anyone took them

    def put(self, item: T) -> bool:
        """Offer the newest item; True when it replaced one nobody had taken (that one is lost)."""
        with self._cond:
            stale = self._item is not None
            self._item = item
            self.put_count += 1
            self.replaced += stale
            self._cond.notify()
        return stale

    def take(self, timeout_s: Optional[float] = None) -> Optional[T]:
        """The newest item (removed from the slot), waiting up to `timeout_s`; None on timeout
        or once closed."""
        with self._cond:
            if self._item is None and not self._closed:
                self._cond.wait(timeout_s)
            if self._closed:
                return None
            item, self._item = self._item, None
            return item

    def close(self) -> None:
        """Wake the taker for good (shutdown)."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    @property
    def closed(self) -> bool:
        return self._closed
