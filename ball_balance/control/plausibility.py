"""Plausibility of the controllers' inputs, judged per message before anything is stored
(a bad message must never replace a good one, even for one tick). No ROS.

`BallStateGate` decides whether one ball state may be used:
  - its stamp is neither in the future (beyond `max_stamp_ahead_s`: clocks of two processes
    under simulated time differ by a /clock period) nor older than `max_age_s` (the oldest
    state the controller would still act on through prediction, max_prediction_s: a state
    that is only late is newer news than the one it replaces), and it is newer than the state
    in use (a second source cannot take the filter back in time);
  - its numbers are finite, the ball is on the plate and no faster than `max_speed_m_s`;
  - its position is consistent with the recent motion: within `max_jump_m` (plus what the
    largest acceleration the plate can give adds) of where the last accepted state,
    moving at its velocity, would be now. A real jump (the tracker re-acquired the ball
    elsewhere) is accepted once `reacquire_count` states in a row agree with one another.
States with tracking_valid false pass the stamp checks only: they carry the news of a loss.

`SourceLock` keeps the states of the one publisher the controller locked onto. rclpy on
Jazzy does not give a message's publisher (MessageInfo has no publisher_gid before Kilted);
it gives the DDS publication sequence number, which each writer counts on its own from 1.
One writer's numbers rise in small steps, so a message whose number does not continue the
locked stream comes from another writer. A newer rclpy's publisher_gid, when present, is
used instead. The lock moves to another stream only when the locked one has been silent for
`silence_s` and the caller allows it (the node allows it while the graph shows at most one
publisher, so a lone restarted tracker is picked up, and a rogue next to a dead tracker is not).

`Heartbeat` notices a silent peer (/joint_states, /clock) and its return.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, List, Mapping, Optional

from ball_balance.control.safety import BallObservation


@dataclass(frozen=True)
class GateConfig:
    max_age_s: float = 0.5
    max_stamp_ahead_s: float = 0.2
    plate_half_side_m: float = 0.2285
    max_speed_m_s: float = 2.0
    max_jump_m: float = 0.03
    max_accel_m_s2: float = 2.0      # the largest ball acceleration the plate can cause (k g sin(tilt))
    motion_window_s: float = 0.5     # consistency is judged against a state at most this much older
    reacquire_count: int = 3


def gate_config(values: Mapping[str, Any], plate_half_side_m: float, k_g: float) -> GateConfig:
    """GateConfig from the controllers' validated parameter values."""
    return GateConfig(max_age_s=values["max_prediction_s"], max_stamp_ahead_s=values["max_stamp_ahead_s"],
                      plate_half_side_m=plate_half_side_m, max_speed_m_s=values["max_ball_speed_m_s"],
                      max_jump_m=values["max_ball_jump_m"],
                      max_accel_m_s2=k_g * math.sin(values["max_total_tilt_rad"]))


@dataclass(frozen=True)
class Verdict:
    ok: bool
    kind: str = ""     # short key for counting: future, stale, old, non_finite, off_plate, too_fast, jump
    reason: str = ""   # one line for the log


ACCEPTED = Verdict(True)


@dataclass
class _Motion:
    stamp_s: float
    x: float
    y: float
    vx: float
    vy: float

    def distance_from_prediction(self, stamp_s: float, x: float, y: float) -> float:
        dt = stamp_s - self.stamp_s
        return math.hypot(x - (self.x + self.vx * dt), y - (self.y + self.vy * dt))


class BallStateGate:
    def __init__(self, cfg: GateConfig):
        self.cfg = cfg
        self.reset()

    def reset(self) -> None:
        self._newest_stamp_s = -math.inf
        self._anchor: Optional[_Motion] = None    # last accepted valid state
        self._pending: List[_Motion] = []         # consecutive inconsistent but mutually consistent states

    def check(self, now_s: float, stamp_s: float, obs: BallObservation) -> Verdict:
        """Whether the state captured at `stamp_s` may be used at `now_s` (same clock)."""
        cfg = self.cfg
        age = now_s - stamp_s
        if not math.isfinite(age):
            return Verdict(False, "non_finite", "non-finite stamp")
        if age < -cfg.max_stamp_ahead_s:
            return Verdict(False, "future", f"stamp {-age:.2f} s in the future")
        if age > cfg.max_age_s:
            return Verdict(False, "stale", f"stamp {age:.2f} s old (limit {cfg.max_age_s:.2f} s)")
        if stamp_s <= self._newest_stamp_s:
            return Verdict(False, "old", f"stamp {self._newest_stamp_s - stamp_s:.3f} s older than the state in use")
        if obs.tracking_valid:
            verdict = self._check_valid(stamp_s, obs)
            if not verdict.ok:
                return verdict
        self._newest_stamp_s = stamp_s
        return ACCEPTED

    def _check_valid(self, stamp_s: float, obs: BallObservation) -> Verdict:
        cfg = self.cfg
        if not all(math.isfinite(v) for v in (obs.x, obs.y, obs.vx, obs.vy)):
            return Verdict(False, "non_finite", "non-finite position or velocity")
        if max(abs(obs.x), abs(obs.y)) > cfg.plate_half_side_m:
            return Verdict(False, "off_plate", f"position ({obs.x:.3f}, {obs.y:.3f}) m is off the plate")
        speed = math.hypot(obs.vx, obs.vy)
        if speed > cfg.max_speed_m_s:
            return Verdict(False, "too_fast", f"speed {speed:.2f} m/s > {cfg.max_speed_m_s:.2f} m/s")
        state = _Motion(stamp_s, obs.x, obs.y, obs.vx, obs.vy)
        anchor = self._anchor
        if anchor is not None and stamp_s - anchor.stamp_s <= cfg.motion_window_s:
            miss = anchor.distance_from_prediction(stamp_s, obs.x, obs.y)
            if miss > self._tolerance(stamp_s - anchor.stamp_s):
                if not self._reacquired(state):
                    return Verdict(False, "jump", f"position {miss * 1e3:.0f} mm from where the ball was heading")
        self._anchor, self._pending = state, []
        return ACCEPTED

    def _tolerance(self, dt_s: float) -> float:
        return self.cfg.max_jump_m + 0.5 * self.cfg.max_accel_m_s2 * dt_s * dt_s

    def _reacquired(self, state: _Motion) -> bool:
        """True when `state` completes `reacquire_count` mutually consistent rejected states."""
        last = self._pending[-1] if self._pending else None
        consistent = (last is not None and state.stamp_s - last.stamp_s <= self.cfg.motion_window_s
                      and last.distance_from_prediction(state.stamp_s, state.x, state.y)
                      <= self._tolerance(state.stamp_s - last.stamp_s))
        self._pending = [*self._pending, state] if consistent else [state]
        return len(self._pending) >= self.cfg.reacquire_count


@dataclass
class _Stream:
    head: int              # last sequence number seen
    last_s: float          # receipt time of that message
    rate_hz: float = 0.0   # sequence numbers per second (running estimate)

    def advance(self, seq: int, now_s: float) -> None:
        dt = now_s - self.last_s
        if dt > 0:
            self.rate_hz += 0.2 * ((seq - self.head) / dt - self.rate_hz) if self.rate_hz else (seq - self.head) / dt
        self.head, self.last_s = seq, now_s

    def expected(self, now_s: float) -> float:
        return self.head + self.rate_hz * (now_s - self.last_s)


@dataclass
class SourceLock:
    max_seq_gap: int = 200         # samples one writer may lose between two we receive
    silence_s: float = 3.0         # the locked writer silent this long may be replaced (a tracker
                                   # stalls for a second under load; a restart takes longer)
    forget_s: float = 30.0         # streams unheard this long are forgotten
    locked_key: Optional[Any] = None
    _streams: dict = field(default_factory=dict)
    _next_key: int = 0

    def reset(self) -> None:
        self.locked_key, self._streams = None, {}

    def observe(self, now_s: float, seq: Optional[int], gid: Optional[bytes] = None,
                relock_allowed: bool = True) -> tuple[bool, str]:
        """Whether a message (receipt time now_s, publication sequence number, publisher gid if
        known) comes from the locked publisher; the str says what changed: "locked" (a lock was
        taken or moved), "ambiguous" (the locked one is silent and moving is not allowed),
        "foreign" (another publisher), "" (nothing)."""
        if gid is None and not seq:
            return True, ""    # nothing identifies the writer: the other gates must do
        key = bytes(gid) if gid is not None else self._stream_of(int(seq), now_s)
        stream = self._streams.get(key)
        if stream is None:
            self._streams[key] = _Stream(int(seq or 0), now_s)
        else:
            stream.advance(int(seq or 0), now_s)
        self._forget(now_s)
        return self._decide(key, now_s, relock_allowed)

    def may_move(self, now_s: float) -> bool:
        """A message from another stream now would take the lock (if allowed)."""
        locked = self._streams.get(self.locked_key)
        return locked is None or now_s - locked.last_s > self.silence_s

    def _decide(self, key, now_s: float, relock_allowed: bool) -> tuple[bool, str]:
        if key == self.locked_key:
            return True, ""
        if self.may_move(now_s):
            if not relock_allowed:
                return False, "ambiguous"
            self.locked_key = key
            return True, "locked"
        return False, "foreign"

    def _stream_of(self, seq: int, now_s: float):
        """The stream `seq` continues: above its last number by at most max_seq_gap, and
        nearest to where its rate says it should be now (two writers whose numbers cross
        stay apart when their rates differ)."""
        best, best_miss = None, None
        for key, stream in self._streams.items():
            if isinstance(key, bytes) or not 0 < seq - stream.head <= self.max_seq_gap:
                continue
            miss = abs(seq - stream.expected(now_s))
            if best_miss is None or miss < best_miss:
                best, best_miss = key, miss
        if best is None:
            best, self._next_key = self._next_key, self._next_key + 1
        return best

    def _forget(self, now_s: float) -> None:
        for key in [k for k, s in self._streams.items() if k != self.locked_key and now_s - s.last_s > self.forget_s]:
            del self._streams[key]


class Heartbeat:
    """A peer that should be heard from at least every `timeout_s` (receipt times, steady clock)."""

    def __init__(self, timeout_s: float):
        self.timeout_s = timeout_s
        self.last_s: Optional[float] = None
        self.lost_since_s: Optional[float] = None

    def beat(self, now_s: float) -> None:
        self.last_s = now_s

    def check(self, now_s: float) -> str:
        """"lost" when it just went silent, "back" when it was lost and is heard again, else ""."""
        if self.last_s is None:
            return ""
        silent = now_s - self.last_s > self.timeout_s
        if silent and self.lost_since_s is None:
            self.lost_since_s = self.last_s
            return "lost"
        if not silent and self.lost_since_s is not None:
            self.lost_since_s = None
            return "back"
        return ""

    @property
    def lost(self) -> bool:
        return self.lost_since_s is not None
