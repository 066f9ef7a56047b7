"""What the live view's page shows, kept as plain numbers and strings (no ROS).

The node feeds it from its subscriptions on the executor's thread and asks it for a
`snapshot()` a few times a second while a page is connected, and once for each GET /api/state;
the snapshot is a new dict of plain values (JSON-ready), handed to the web server's thread as it
is and never changed after.

Times are the messages' stamps in seconds (the graph's clock: simulated time in simulation), so
the path and the error plot show the last seconds of the run as the camera saw them, however
fast the simulation runs; "now" is the newest stamp seen.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Deque, Dict, Optional, Tuple

ENGAGED_TIMEOUT_S = 0.5     # the controller publishes /ball_reference only while engaged
EVENTS_KEPT = 8             # the robot manager's last events shown
SAMPLE_PERIOD_S = 0.05      # the path and error histories keep one sample per this


@dataclass
class Ball:
    x: float = 0.0
    y: float = 0.0
    vx: float = 0.0
    vy: float = 0.0
    tracking_valid: bool = False
    ball_found: bool = False
    markers_found: int = 0
    pixel_u: float = 0.0
    pixel_v: float = 0.0


@dataclass
class RobotManager:
    present: bool = False
    lifecycle_state: str = "unknown"
    emergency_stop_active: Optional[bool] = None   # None: nothing received on the latched topic
    events: Deque[dict] = field(default_factory=lambda: deque(maxlen=EVENTS_KEPT))


def _finite(*values: float) -> bool:
    return all(isinstance(v, (int, float)) and math.isfinite(v) for v in values)


class LiveModel:
    def __init__(self, error_window_s: float = 10.0, path_window_s: float = 3.0):
        self.error_window_s, self.path_window_s = error_window_s, path_window_s
        self.ball: Optional[Ball] = None
        self.ball_time_s = -math.inf
        self.ball_count = 0
        self.latest_s = 0.0                            # the newest stamp seen
        self.refused = 0                               # ball states with non-finite values
        self.reference: Optional[Tuple[float, float]] = None
        self.reference_time_s = -math.inf
        self.path: Deque[Tuple[float, float, float]] = deque()     # (t, x, y)
        self.errors: Deque[Tuple[float, float, float]] = deque()   # (t, e_x, e_y) = reference - ball
        self.arm_speed_rad_s: Optional[float] = None   # max |joint velocity| of the newest joint state
        self.arm_time_s = -math.inf
        self.controller: Dict[str, object] = {"node": "", "present": False, "parameters": {}, "plant": ""}
        self.manager = RobotManager()
        self.frames_sent = 0
        self.image: Dict[str, object] = {"width": 0, "height": 0, "topic": "", "every_n": 1}

    # ---- inputs ----------------------------------------------------------------------------
    def on_ball(self, ball: Ball, now_s: float) -> bool:
        """A ball state; False (and counted) when a value is not finite."""
        if not _finite(ball.x, ball.y, ball.vx, ball.vy, ball.pixel_u, ball.pixel_v):
            self.refused += 1
            return False
        self.ball, self.ball_time_s = ball, now_s
        self.latest_s = max(self.latest_s, now_s)
        self.ball_count += 1
        if ball.tracking_valid:
            self._sample(self.path, (now_s, ball.x, ball.y), self.path_window_s)
            if self.reference is not None and abs(now_s - self.reference_time_s) < ENGAGED_TIMEOUT_S:
                rx, ry = self.reference
                self._sample(self.errors, (now_s, rx - ball.x, ry - ball.y), self.error_window_s)
        return True

    def on_reference(self, x: float, y: float, now_s: float) -> None:
        if _finite(x, y):
            self.reference, self.reference_time_s = (x, y), now_s
            self.latest_s = max(self.latest_s, now_s)

    def on_joint_velocities(self, velocities, now_s: float) -> None:
        speeds = [abs(v) for v in velocities if _finite(v)]
        self.arm_speed_rad_s = max(speeds) if speeds else None
        self.arm_time_s = now_s
        self.latest_s = max(self.latest_s, now_s)

    def on_manager_event(self, level: int, message: str, values: Dict[str, str], now_s: float) -> None:
        """An event of the robot manager; now_s: its arrival on the caller's clock (shown as given)."""
        self.manager.events.appendleft({"t": now_s, "level": int(level), "message": message,
                                        "event": values.get("event", ""), "source": values.get("source", "")})
        state = values.get("lifecycle_state")
        if state:
            self.manager.lifecycle_state = state

    @staticmethod
    def _sample(history: deque, sample: tuple, window_s: float) -> None:
        """Append at most one sample per SAMPLE_PERIOD_S; drop those older than the window."""
        if history and sample[0] - history[-1][0] < SAMPLE_PERIOD_S:
            return
        history.append(sample)
        while history and sample[0] - history[0][0] > window_s:
            history.popleft()

    # ---- output ----------------------------------------------------------------------------
    def snapshot(self, now_s: Optional[float] = None) -> dict:
        """Everything the page shows, as a new JSON-ready dict (now_s: the newest stamp seen)."""
        now_s = self.latest_s if now_s is None else now_s
        ball = None
        if self.ball is not None:
            b = self.ball
            ball = {"x": b.x, "y": b.y, "vx": b.vx, "vy": b.vy, "tracking_valid": b.tracking_valid,
                    "ball_found": b.ball_found, "markers_found": b.markers_found, "pixel_u": b.pixel_u,
                    "pixel_v": b.pixel_v, "age_s": now_s - self.ball_time_s, "count": self.ball_count}
        engaged = self.reference is not None and now_s - self.reference_time_s < ENGAGED_TIMEOUT_S
        manager = self.manager
        return {
            "t": now_s,
            "ball": ball,
            "reference": list(self.reference) if self.reference is not None else None,
            "path": [[round(x, 5), round(y, 5)] for _, x, y in self.path],
            "errors": [[round(t - now_s, 3), round(ex, 5), round(ey, 5)] for t, ex, ey in self.errors],
            "error_window_s": self.error_window_s,
            "arm": {"speed_rad_s": self.arm_speed_rad_s,
                    "age_s": now_s - self.arm_time_s if math.isfinite(self.arm_time_s) else None},
            "controller": dict(self.controller, engaged=engaged),
            "robot_manager": {"present": manager.present, "lifecycle_state": manager.lifecycle_state,
                              "emergency_stop_active": manager.emergency_stop_active,
                              "events": list(manager.events)},
            "image": dict(self.image, frames_sent=self.frames_sent),
            "refused": self.refused,
        }
