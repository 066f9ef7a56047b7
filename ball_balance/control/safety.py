"""Safety supervisor: when the controller may act (docs/design.md section 6, Safety).

States (`Mode`):
  HOMING     start-up: drive the arm to home, never tilt for the ball.
  READY      at home, waiting for a healthy ball state.
  ENGAGED    controlling the ball.
  HOLDING    ENGAGED but the state went unhealthy, for at most `loss_hold_s`: a state that is
             only late is still used through its prediction; anything else holds the last tilt.
  RETURNING  unhealthy beyond `loss_hold_s`: go back to home smoothly, then READY; a state
             healthy again for `healthy_before_engage_s` on the way re-engages from where the
             plate is.

A ball state is healthy when tracking_valid, its plate pose is good enough, all numbers are
finite, the ball is on the plate, and its age is within ball_state_max_age_s. "Good enough":
when the tracker says how uncertain the ball's position is because of the plate pose
(`position_std_m` > 0, from /plate_pose), that figure must be within max_position_std_m,
whatever the marker count (a hand over one or two markers leaves a usable pose); when it
does not say (0.0, a tracker without /plate_pose), markers_found >= min_markers.

Hysteresis: HOLDING returns to ENGAGED only after the state has been healthy for
`healthy_before_engage_s` without a break, so a state that is fresh one tick and stale the
next (a stalling tracker under load) does not flip the mode at the tick rate. A state that is only
late (otherwise healthy, at most `max_late_s` old: the pipeline predicts it forward) keeps
HOLDING controlling; `loss_hold_s` counts from the moment the state stops being usable
(invalid, poor pose, or older than max_late_s) and a brief recovery does not restart it. Leaving ENGAGED/HOLDING for
RETURNING asks the caller to reset its integrators (`reset_requested`). Smoothness itself
comes from the command shaper (per-joint step clip).
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Optional, Tuple


class Mode(enum.Enum):
    HOMING = "homing"
    READY = "ready"
    ENGAGED = "engaged"
    HOLDING = "holding"
    RETURNING = "returning"


# the tracker's level offset (BallObservation.level_offset_rad) arrives on this topic, and one
# stamped this much away from the ball state it is paired with is not used
LEVEL_OFFSET_TOPIC = "/ball_level_offset"
LEVEL_OFFSET_MAX_AGE_S = 0.5


@dataclass(frozen=True)
class SafetyConfig:
    min_markers: int = 3          # markers needed in a frame to trust the plate pose (std unknown)
    max_position_std_m: float = 0.005  # ball position 1-sigma from the plate pose (std known)
    ball_state_max_age_s: float = 0.25    # a state older than this is stale
    loss_hold_s: float = 0.3              # how long to hold the last tilt before returning home
    healthy_before_engage_s: float = 0.1  # healthy this long without a break to leave HOLDING
    max_late_s: float = 0.5       # a late but otherwise healthy state is acted on (predicted) up to this age
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
    # 1-sigma error of (x, y) caused by the plate pose [m]; 0.0 = not known (markers rule),
    # inf = no usable pose
    position_std_m: float = 0.0
    # the plate-level offset per axis [rad] the tracker's filter estimates: the tilt (in the
    # commands' convention) that holds the ball still against a constant disturbance; None when
    # the tracker does not estimate it (the controller's plant estimate then does)
    level_offset_rad: Optional[Tuple[float, float]] = None


class SafetySupervisor:
    def __init__(self, cfg: SafetyConfig):
        self.cfg = cfg
        self.mode = Mode.HOMING
        self._unhealthy_since: Optional[float] = None
        self._healthy_since: Optional[float] = None   # in HOLDING: start of the current healthy run
        self.reset_requested = False   # set on a transition that must clear integrators
        self.reason = "start-up"       # why the current mode was entered (for logs)

    def pose_problem(self, obs: BallObservation) -> str:
        """Why the plate pose behind `obs` is not good enough to act on ("" when it is)."""
        std = obs.position_std_m
        if std != 0.0:   # known (or inf / NaN: no usable pose)
            if not std <= self.cfg.max_position_std_m:
                return f"position std {std * 1e3:.1f} mm > {self.cfg.max_position_std_m * 1e3:.1f} mm"
            return ""
        if obs.markers_found < self.cfg.min_markers:
            return f"markers {obs.markers_found} < {self.cfg.min_markers}"
        return ""

    def usable_except_age(self, obs: Optional[BallObservation]) -> bool:
        """The state would be healthy if it were not late (prediction can bridge the gap)."""
        if obs is None or not obs.tracking_valid or self.pose_problem(obs):
            return False
        return all(math.isfinite(v) for v in (obs.x, obs.y, obs.vx, obs.vy, obs.age_s))

    def healthy(self, obs: Optional[BallObservation]) -> tuple[bool, str]:
        if obs is None:
            return False, "no ball state yet"
        if not all(math.isfinite(v) for v in (obs.x, obs.y, obs.vx, obs.vy, obs.age_s)):
            return False, "non-finite ball state"
        if not obs.tracking_valid:
            return False, "tracking not valid"
        pose = self.pose_problem(obs)
        if pose:
            return False, pose
        if obs.age_s > self.cfg.ball_state_max_age_s:
            return False, f"state stale ({obs.age_s:.2f} s old)"
        if max(abs(obs.x), abs(obs.y)) > self.cfg.plate_half_side_m:
            return False, "ball off the plate"
        return True, ""

    def update(self, now_s: float, obs: Optional[BallObservation], at_home: bool) -> Mode:
        """Advance the state machine one tick and return the mode to act in."""
        ok, why = self.healthy(obs)
        self.reset_requested = False
        mode = self.mode
        if mode == Mode.RETURNING and ok:
            # the ball is seen again on its way home (a stall, a hand lifted): take it up from
            # where the plate is once the state has stayed healthy for healthy_before_engage_s,
            # instead of levelling a plate that still carries the ball
            if self._healthy_since is None:
                self._healthy_since = now_s
            if now_s - self._healthy_since >= self.cfg.healthy_before_engage_s:
                self._go(Mode.ENGAGED, f"re-acquired while returning (healthy for {now_s - self._healthy_since:.2f} s)")
                self.reset_requested = True
            elif at_home:
                self._go(Mode.READY, "at home")
        elif mode in (Mode.HOMING, Mode.RETURNING):
            self._healthy_since = None
            if at_home:
                self._go(Mode.READY, "at home")
        elif mode == Mode.READY:
            if ok:
                self._go(Mode.ENGAGED, "healthy ball state")
                self.reset_requested = True
        elif mode == Mode.ENGAGED:
            if not ok:
                self._unhealthy_since, self._healthy_since = now_s, None
                self._go(Mode.HOLDING, why)
        elif mode == Mode.HOLDING:
            if ok:
                if self._healthy_since is None:
                    self._healthy_since = now_s
                if now_s - self._healthy_since >= self.cfg.healthy_before_engage_s:
                    self._go(Mode.ENGAGED, f"recovered (healthy for {now_s - self._healthy_since:.2f} s)")
            else:
                self._healthy_since = None
                self.reason = why
                if self.usable_except_age(obs) and obs.age_s <= self.cfg.max_late_s:
                    self._unhealthy_since = now_s   # late, still acted on: loss_hold_s waits
                elif now_s - self._unhealthy_since > self.cfg.loss_hold_s:
                    self._go(Mode.RETURNING, why)
                    self.reset_requested = True
        return self.mode

    def _go(self, mode: Mode, reason: str) -> None:
        self.mode, self.reason = mode, reason
