"""A tf2-like transform buffer in plain Python: a time-indexed tree of frames.

Each child frame has one parent and a cache of T_parent_child samples (dynamic: the last
`cache_time_s` seconds; static: one sample valid at every time). `lookup_transform(target,
source, time_ns)` walks both frames up to their common ancestor, interpolates every edge
at `time_ns` (linear translation, slerp rotation) and returns T_target_source: the pose of
`source` in `target`, mapping points given in source into target (tf2's convention).
time_ns == 0 means "latest available": the newest time at which every dynamic edge of the
chain has data. Times are integer nanoseconds (ROS time).

Errors name the frames and times: LookupException (unknown frame), ConnectivityException
(frames in two separate trees), ExtrapolationException (time outside the cached data).
All derive from TransformException. Thread-safe (the ROS listener fills it from a callback).
"""
from __future__ import annotations

import bisect
import threading
import time as _time
from typing import Dict, List, Optional, Tuple

from ball_balance.tf.transform import Transform

NS = 1_000_000_000
MAX_DEPTH = 1000  # a deeper chain is a loop in the tree


class TransformException(Exception):
    """Base of every TF lookup error (its message is one line naming frames and times)."""


class LookupException(TransformException):
    """A frame is not in the buffer."""


class ConnectivityException(TransformException):
    """The two frames are not in the same tree."""


class ExtrapolationException(TransformException):
    """The requested time lies outside the data cached for an edge of the chain."""


def format_time(stamp_ns: int) -> str:
    return f"{stamp_ns / NS:.6f}"


class _EdgeCache:
    """T_parent_child samples of one edge, sorted by time."""

    def __init__(self, parent: str, static: bool, cache_time_ns: int):
        self.parent, self.static, self.cache_time_ns = parent, static, cache_time_ns
        self.stamps: List[int] = []
        self.transforms: List[Transform] = []

    def insert(self, stamp_ns: int, transform: Transform) -> None:
        if self.static:  # one sample, valid at every time
            self.stamps, self.transforms = [stamp_ns], [transform]
            return
        i = bisect.bisect_left(self.stamps, stamp_ns)
        if i < len(self.stamps) and self.stamps[i] == stamp_ns:
            self.transforms[i] = transform
        else:
            self.stamps.insert(i, stamp_ns)
            self.transforms.insert(i, transform)
        oldest_kept = self.stamps[-1] - self.cache_time_ns
        drop = bisect.bisect_left(self.stamps, oldest_kept)
        if drop:
            del self.stamps[:drop], self.transforms[:drop]

    @property
    def newest(self) -> int:
        return self.stamps[-1]

    def at(self, stamp_ns: int, child: str) -> Transform:
        """T_parent_child at stamp_ns (0: newest), interpolated between samples."""
        if self.static or stamp_ns == 0:
            return self.transforms[-1]
        oldest, newest = self.stamps[0], self.stamps[-1]
        if stamp_ns > newest or stamp_ns < oldest:
            where = "future" if stamp_ns > newest else "past"
            data = (f"the latest data is at time {format_time(newest)}" if stamp_ns > newest
                    else f"the earliest data is at time {format_time(oldest)}")
            raise ExtrapolationException(
                f"Lookup would require extrapolation into the {where}. Requested time "
                f"{format_time(stamp_ns)} but {data}, when looking up transform from frame "
                f"[{child}] to frame [{self.parent}]")
        i = bisect.bisect_left(self.stamps, stamp_ns)
        if self.stamps[i] == stamp_ns:
            return self.transforms[i]
        t0, t1 = self.stamps[i - 1], self.stamps[i]
        return self.transforms[i - 1].interpolate(self.transforms[i], (stamp_ns - t0) / (t1 - t0))


class BufferCore:
    """The frame tree and its per-edge time caches (no ROS dependency)."""

    def __init__(self, cache_time_s: float = 10.0):
        self.cache_time_ns = int(cache_time_s * NS)
        self._edges: Dict[str, _EdgeCache] = {}  # child frame -> edge to its parent
        self._frames: set = set()
        self._changed = threading.Condition()

    # --- filling -------------------------------------------------------------------
    def set_transform(self, parent: str, child: str, stamp_ns: int, transform: Transform,
                      static: bool = False) -> None:
        """Store T_parent_child at stamp_ns. A frame that changes parent starts afresh."""
        parent, child = _clean(parent, "parent"), _clean(child, "child")
        if parent == child:
            raise TransformException(f"frame [{child}] cannot be its own parent")
        with self._changed:
            edge = self._edges.get(child)
            if edge is None or edge.parent != parent or edge.static != static:
                edge = self._edges[child] = _EdgeCache(parent, static, self.cache_time_ns)
            edge.insert(int(stamp_ns), transform)
            self._frames.update((parent, child))
            self._changed.notify_all()

    def clear(self) -> None:
        with self._changed:
            self._edges.clear()
            self._frames.clear()

    # --- queries -------------------------------------------------------------------
    def all_frames(self) -> List[str]:
        with self._changed:
            return sorted(self._frames)

    def parent_of(self, frame: str) -> Optional[str]:
        with self._changed:
            edge = self._edges.get(frame)
            return edge.parent if edge else None

    def can_transform(self, target: str, source: str, stamp_ns: int = 0) -> bool:
        try:
            self.lookup_transform(target, source, stamp_ns)
            return True
        except TransformException:
            return False

    def lookup_transform(self, target: str, source: str, stamp_ns: int = 0) -> Tuple[Transform, int]:
        """(T_target_source, stamp_ns used): the pose of `source` in `target` at stamp_ns.

        stamp_ns == 0 asks for the latest time all edges of the chain have data; the stamp
        returned is then that time (0 for an all-static chain).
        """
        with self._changed:
            for frame, role in ((target, "target_frame"), (source, "source_frame")):
                if frame not in self._frames:
                    known = ", ".join(sorted(self._frames)) or "none"
                    raise LookupException(
                        f"frame [{frame}] passed as {role} does not exist (known frames: {known})")
            source_up = self._path_to_root(source)
            target_up = self._path_to_root(target)
            target_index = {frame: i for i, frame in enumerate(target_up)}
            common = next((i for i, frame in enumerate(source_up) if frame in target_index), None)
            if common is None:
                raise ConnectivityException(
                    f"Could not find a connection between [{target}] and [{source}] because they "
                    f"are not part of the same tree (roots [{target_up[-1]}] and [{source_up[-1]}])")
            source_chain = source_up[:common]  # children below the common ancestor
            target_chain = target_up[:target_index[source_up[common]]]
            edges = [self._edges[f] for f in source_chain + target_chain]
            if stamp_ns == 0:
                dynamic = [e.newest for e in edges if not e.static]
                stamp_ns = min(dynamic) if dynamic else 0
            T_common_source = self._compose(source_chain, stamp_ns)
            T_common_target = self._compose(target_chain, stamp_ns)
            return T_common_target.inverse() * T_common_source, stamp_ns

    def lookup_transform_full(self, target: str, target_ns: int, source: str, source_ns: int,
                              fixed: str) -> Transform:
        """T_target(target_ns)_source(source_ns) through a frame `fixed` that does not move
        between the two times (tf2's advanced lookup; e.g. a ball seen by a moving camera at
        capture time, expressed in the plate frame now, with fixed = "world")."""
        T_fixed_source, _ = self.lookup_transform(fixed, source, source_ns)
        T_target_fixed, _ = self.lookup_transform(target, fixed, target_ns)
        return T_target_fixed * T_fixed_source

    def wait_for_transform(self, target: str, source: str, stamp_ns: int = 0,
                           timeout_s: float = 0.0) -> Tuple[Transform, int]:
        """lookup_transform, retried as data arrives until timeout_s; then its error."""
        deadline = _time.monotonic() + timeout_s
        while True:
            try:
                return self.lookup_transform(target, source, stamp_ns)
            except TransformException:
                remaining = deadline - _time.monotonic()
                if remaining <= 0:
                    raise
                with self._changed:
                    self._changed.wait(min(remaining, 0.1))

    # --- internals -----------------------------------------------------------------
    def _path_to_root(self, frame: str) -> List[str]:
        path = [frame]
        while frame in self._edges:
            frame = self._edges[frame].parent
            path.append(frame)
            if len(path) > MAX_DEPTH:
                raise TransformException(f"the frame tree has a loop through [{frame}]")
        return path

    def _compose(self, chain: List[str], stamp_ns: int) -> Transform:
        """T_top_bottom for chain = [bottom, ..., child of top], each edge at stamp_ns."""
        result = Transform()
        for child in reversed(chain):
            result = result * self._edges[child].at(stamp_ns, child)
        return result


def _clean(frame: str, role: str) -> str:
    """tf2 frame ids carry no leading slash; an empty id is an error."""
    name = str(frame).lstrip("/")
    if not name:
        raise TransformException(f"empty {role} frame id")
    return name
