"""What ends in a safe stop while the arm may move: the three watchdogs of the robot manager.

Plain Python, no ROS. The node feeds it arrival times (monotonic wall-clock seconds: a
watchdog must fire when the graph's simulated clock itself has stopped) and the hardware
states it learns from the controller manager, and asks `check(now)` every tick while it is
active. The first problem found is returned as (source, reason); sources are the `source`
values of the robot manager's events.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, Optional, Tuple

HARDWARE_ERROR, MANAGER_STALLED, CAMERA_LOST = "hardware_error", "manager_stalled", "camera_lost"


@dataclass
class WatchdogLimits:
    manager_timeout_s: float = 2.0      # no heartbeat from the controller manager this long: stalled
    camera_timeout_s: float = 2.0       # no camera frame this long while the ball is on the plate: lost


@dataclass
class Watchdog:
    limits: WatchdogLimits
    heartbeat_topic: str = "/controller_manager/statistics/values"
    camera_topic: str = "/camera/image_raw"
    last_heartbeat_s: Optional[float] = None
    last_frame_s: Optional[float] = None
    ball_on_plate: bool = False         # as of the tracker's last /ball_state (tracking_valid)
    hardware: Dict[str, str] = field(default_factory=dict)   # component -> lifecycle label

    def arm(self, now_s: float) -> None:
        """At activation: the timeouts count from now (a message seen long ago is not a stall yet)."""
        if self.last_heartbeat_s is not None:
            self.last_heartbeat_s = max(self.last_heartbeat_s, now_s)
        if self.last_frame_s is not None:
            self.last_frame_s = max(self.last_frame_s, now_s)

    def check(self, now_s: float, expected_hardware: str = "active") -> Optional[Tuple[str, str]]:
        """(source, reason) of the first problem, or None. `expected_hardware`: the state every
        listed component must be in (a component that left it reported an error, or was taken
        away from under the robot manager)."""
        for name, state in sorted(self.hardware.items()):
            if state != expected_hardware:
                return HARDWARE_ERROR, (f"hardware '{name}' is {state}, not {expected_hardware} "
                                        "(it reported an error or was switched by someone else)")
        limits = self.limits
        if self.last_heartbeat_s is not None and now_s - self.last_heartbeat_s > limits.manager_timeout_s:
            quiet_s = now_s - self.last_heartbeat_s
            return MANAGER_STALLED, (f"the controller manager stopped updating: nothing on {self.heartbeat_topic} "
                                     f"for {quiet_s:.1f} s (limit {limits.manager_timeout_s:g} s)")
        # a graph without a camera (truth-fed simulation) never had a frame: nothing to lose
        if (self.ball_on_plate and self.last_frame_s is not None
                and now_s - self.last_frame_s > limits.camera_timeout_s):
            return CAMERA_LOST, (f"camera lost with the ball on the plate: no frame on {self.camera_topic} for "
                                 f"{now_s - self.last_frame_s:.1f} s (limit {limits.camera_timeout_s:g} s)")
        return None
