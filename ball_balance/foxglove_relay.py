"""What the Foxglove node decides, without ROS or the Foxglove SDK: when to subscribe to a topic,
which messages to forward, which topic names it accepts.

The node (ball_balance/nodes/foxglove_node.py) advertises one Foxglove channel per topic once the
topic has a publisher, but subscribes to the topic only while a Foxglove client watches its
channel: a graph nobody watches costs nothing. `Watchers` keeps who watches which channel and
says what the node must do when a client subscribes or leaves. A latched topic (transient
local: /tf_static, /robot_description) is subscribed anew for every client that joins, so that
its publishers send their kept messages again and the newcomer receives them too.

`clock_ns` reads a /clock message's time from its CDR bytes: with simulated time, the node
tells its clients the graph's time and stamps what it forwards with it.
"""
from __future__ import annotations

import struct
from typing import Dict, Iterable, Optional, Set

SUBSCRIBE = "subscribe"      # the first client watches: subscribe to the topic
RESUBSCRIBE = "resubscribe"  # another client joins a latched topic: subscribe anew (the kept messages again)
UNSUBSCRIBE = "unsubscribe"  # the last client left: drop the subscription

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")


class Watchers:
    """The clients watching each channel (by id); one instance per node, used by one thread."""

    def __init__(self):
        self._clients: Dict[int, Set[int]] = {}

    def watching(self, channel_id: int) -> int:
        """How many clients watch the channel."""
        return len(self._clients.get(channel_id, ()))

    @property
    def any(self) -> bool:
        """True while some client watches some channel."""
        return any(self._clients.values())

    def joined(self, channel_id: int, client_id: int, latched: bool) -> Optional[str]:
        """A client subscribed to the channel: SUBSCRIBE, RESUBSCRIBE or None (nothing to do)."""
        clients = self._clients.setdefault(channel_id, set())
        if client_id in clients:
            return None
        clients.add(client_id)
        if len(clients) == 1:
            return SUBSCRIBE
        return RESUBSCRIBE if latched else None

    def left(self, channel_id: int, client_id: int) -> Optional[str]:
        """A client unsubscribed from the channel or disconnected: UNSUBSCRIBE or None."""
        clients = self._clients.get(channel_id)
        if not clients or client_id not in clients:
            return None
        clients.discard(client_id)
        return None if clients else UNSUBSCRIBE


class RateLimit:
    """Lets at most max_rate_hz messages a second through, on average and over any long stretch.

    Messages are let through on a schedule of one per period; one may come up to a quarter of a
    period early, so that a stream at twice the rate with some jitter keeps every other message
    instead of every third. After a gap the schedule restarts from the message let through, and
    two messages are never let through less than 3/4 of a period apart (a burst yields one).
    max_rate_hz 0 lets every message through. Times are in nanoseconds of a monotonic clock.
    """

    def __init__(self, max_rate_hz: float):
        self.period_ns = int(1e9 / max_rate_hz) if max_rate_hz > 0 else 0
        self._next_ns: Optional[int] = None  # when the next message is due

    def allow(self, now_ns: int) -> bool:
        if self._next_ns is not None and now_ns < self._next_ns - self.period_ns // 4:
            return False
        if self._next_ns is None:
            self._next_ns = now_ns + self.period_ns
        else:
            self._next_ns = max(self._next_ns + self.period_ns, now_ns + self.period_ns)
        return True


# CDR encapsulation (2 bytes of representation id, 2 of options) -> byte order of the body
_CDR_BYTE_ORDER = {b"\x00\x00": ">", b"\x00\x01": "<"}


def clock_ns(cdr: bytes) -> int:
    """The time of a serialized rosgraph_msgs/Clock (builtin_interfaces/Time clock), in ns.

    The body is int32 sec, uint32 nanosec right after the 4-byte encapsulation header.
    Raises ValueError for bytes that are not a plain CDR Clock.
    """
    order = _CDR_BYTE_ORDER.get(bytes(cdr[:2]))
    if order is None or len(cdr) < 12:
        raise ValueError(f"not a serialized rosgraph_msgs/Clock: {bytes(cdr[:12]).hex()}")
    sec, nanosec = struct.unpack_from(f"{order}iI", cdr, 4)
    return sec * 1_000_000_000 + nanosec


def is_image(type_name: str) -> bool:
    """True for the image types the image rate limit applies to."""
    return type_name in IMAGE_TYPES


def topic_list_problem(topics: Iterable[str]) -> Optional[str]:
    """Why a list of topic names is unusable (for the `topics` parameter), or None."""
    topics = list(topics)
    if not topics:
        return "must name at least one topic"
    for name in topics:
        if not isinstance(name, str) or not name.startswith("/") or name.endswith("/") or " " in name:
            return f"has {name!r}: give absolute topic names such as /ball_state"
    repeated = sorted({name for name in topics if topics.count(name) > 1})
    if repeated:
        return f"names {', '.join(repeated)} more than once"
    return None
