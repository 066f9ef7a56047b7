"""Safety supervisor: when the controller may act (DESIGN.md section 6, Safety).

States (`Mode`):
  HOMING     start-up: drive the arm to home, never tilt for the ball.
  READY      at home, waiting for a healthy ball state.
  ENGAGED    controlling the ball.
  HOLDING    ENGAGED but the state went unhealthy, for at most `grace_s`: a state that is
             only late is still used through its prediction; anything else holds the last tilt.
  RETURNING  unhealthy beyond the grace period: go back to home smoothly, then READY.

A ball state is healthy when tracking_valid, markers_found >= min_markers, all numbers are
finite, the ball is on the plate, and its age is within stale_after_s. Leaving ENGAGED/
HOLDING for RETURNING asks the caller to reset its integrators (`reset_requested`).
Smoothness itself comes from the command shaper (per-joint step clip + low-pass).
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Optional


class Mode(enum.Enum):
    HOMING = "homing"
    READY = "ready"
    ENGAGED = "engaged"
    HOLDING = "holding"
    RETURNING = "returning"


@dataclass(frozen=True)
class SafetyConfig:
    min_markers: int = 3          # markers needed in a frame to trust the plate pose
    stale_after_s: float = 0.25   # a state older than this is stale
    grace_s: float = 0.3          # how long to hold the last tilt before returning home
    home_tolerance_rad: float = 0.01  # max |q - q_home| to count as "at home"
    plate_half_side_m: float = 0.2285


@dataclass(frozen=True)
class BallObservation:
    """What the supervisor needs from a BallState (plain numbers, no ROS)."""

    x: float
    y: float
    vx: float
    vy: float
    tracking_valid: bool
    markers_found: int
    age_s: float


class SafetySupervisor:
    def __init__(self, cfg: SafetyConfig):
        self.cfg = cfg
        self.mode = Mode.HOMING
        self._unhealthy_since: Optional[float] = None
        self.reset_requested = False   # set on a transition that must clear integrators
        self.reason = "start-up"       # why the current mode was entered (for logs)

    def healthy(self, obs: Optional[BallObservation]) -> tuple[bool, str]:
        if obs is None:
            return False, "no ball state yet"
        if not all(math.isfinite(v) for v in (obs.x, obs.y, obs.vx, obs.vy, obs.age_s)):
            return False, "non-finite ball state"
        if not obs.tracking_valid:
            return False, "tracking not valid"
        if obs.markers_found < self.cfg.min_markers:
            return False, f"markers {obs.markers_found} < {self.cfg.min_markers}"
        if obs.age_s > self.cfg.stale_after_s:
            return False, f"state stale ({obs.age_s:.2f} s old)"
        if max(abs(obs.x), abs(obs.y)) > self.cfg.plate_half_side_m:
            return False, "ball off the plate"
        return True, ""

    def update(self, now_s: float, obs: Optional[BallObservation], at_home: bool) -> Mode:
        """Advance the state machine one tick and return the mode to act in."""
        ok, why = self.healthy(obs)
        self.reset_requested = False
        mode = self.mode
        if mode in (Mode.HOMING, Mode.RETURNING):
            if at_home:
                self._go(Mode.READY, "at home")
        elif mode == Mode.READY:
            if ok:
                self._go(Mode.ENGAGED, "healthy ball state")
                self.reset_requested = True
        elif mode == Mode.ENGAGED:
            if not ok:
                self._unhealthy_since = now_s
                self._go(Mode.HOLDING, why)
        elif mode == Mode.HOLDING:
            if ok:
                self._go(Mode.ENGAGED, "recovered")
            elif now_s - self._unhealthy_since > self.cfg.grace_s:
                self._go(Mode.RETURNING, why)
                self.reset_requested = True
        return self.mode

    def _go(self, mode: Mode, reason: str) -> None:
        self.mode, self.reason = mode, reason
