"""What ends in a safe stop while the arm may move: the watchdogs of the robot manager.

Plain Python, no ROS. The node feeds it arrival times (monotonic wall-clock seconds: a
watchdog must fire when the graph's simulated clock itself has stopped) and the hardware and
controller states it learns from the controller manager, and asks `check(now)` every tick
while it is active. The first problem found is returned as (source, reason); sources are the
`source` values of the robot manager's events.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, Optional, Set, Tuple

HARDWARE_ERROR, CONTROLLER_STOPPED = "hardware_error", "controller_stopped"
MANAGER_STALLED, CAMERA_LOST = "manager_stalled", "camera_lost"


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
    controllers: Dict[str, str] = field(default_factory=dict)   # balancing controller -> lifecycle label
    # the balancing controllers seen active since `forget_controllers`: only a controller that
    # was active can be stopped (the states from before an activation arrive in order, first)
    controllers_seen_active: Set[str] = field(default_factory=set)

    def arm(self, now_s: float) -> None:
        """At activation: the timeouts count from now (a message seen long ago is not a stall yet)."""
        if self.last_heartbeat_s is not None:
            self.last_heartbeat_s = max(self.last_heartbeat_s, now_s)
        if self.last_frame_s is not None:
            self.last_frame_s = max(self.last_frame_s, now_s)

    def watch_controllers(self, states: Dict[str, str]) -> None:
        """The balancing controllers' lifecycle labels, as the controller manager last reported
        them (one that is not loaded is absent)."""
        self.controllers = dict(states)
        self.controllers_seen_active |= {name for name, label in states.items() if label == "active"}

    def forget_controllers(self) -> None:
        """Before an activation: a controller is watched once it has been reported active."""
        self.controllers_seen_active = set()

    def check(self, now_s: float, expected_hardware: str = "active") -> Optional[Tuple[str, str]]:
        """(source, reason) of the first problem, or None. `expected_hardware`: the state every
        listed component must be in (a component that left it reported an error, or was taken
        away from under the robot manager)."""
        for name, state in sorted(self.hardware.items()):
            if state != expected_hardware:
                return HARDWARE_ERROR, (f"hardware '{name}' is {state}, not {expected_hardware} "
                                        "(it reported an error or was switched by someone else)")
        for name in sorted(self.controllers_seen_active):
            state = self.controllers.get(name, "unloaded")
            if state != "active":
                return CONTROLLER_STOPPED, (f"controller '{name}' is {state}, not active (it failed, or someone "
                                            "switched it: deactivate the robot manager before taking the arm)")
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
