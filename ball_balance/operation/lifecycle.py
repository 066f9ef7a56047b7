"""The managed-node lifecycle of ROS 2 (design.ros2.org "Managed nodes"), as plain data.

Ids and labels are those of lifecycle_msgs/msg/State and lifecycle_msgs/msg/Transition, so a
node can answer lifecycle_msgs' services from this table and `ros2py lifecycle` can print
what ros2cli prints. `outcome()` says which primary state a transition ends in, from the
result of its hook (and of on_error), as rcl_lifecycle's state machine does.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Optional

# primary states (lifecycle_msgs/msg/State)
UNKNOWN, UNCONFIGURED, INACTIVE, ACTIVE, FINALIZED = 0, 1, 2, 3, 4
# transition states
CONFIGURING, CLEANINGUP, SHUTTINGDOWN, ACTIVATING, DEACTIVATING, ERRORPROCESSING = 10, 11, 12, 13, 14, 15
STATE_LABELS: Dict[int, str] = {
    UNKNOWN: "unknown", UNCONFIGURED: "unconfigured", INACTIVE: "inactive", ACTIVE: "active",
    FINALIZED: "finalized", CONFIGURING: "configuring", CLEANINGUP: "cleaningup",
    SHUTTINGDOWN: "shuttingdown", ACTIVATING: "activating", DEACTIVATING: "deactivating",
    ERRORPROCESSING: "errorprocessing",
}
PRIMARY_STATES = (UNCONFIGURED, INACTIVE, ACTIVE, FINALIZED)

# hook results (lifecycle_msgs/msg/Transition TRANSITION_CALLBACK_*)
SUCCESS, FAILURE, ERROR = "success", "failure", "error"


@dataclass(frozen=True)
class Transition:
    id: int
    label: str
    start: int      # primary state it starts from
    via: int        # the transition state its hook runs in
    goal: int       # primary state on success

    def describe(self) -> str:
        return f"{self.label} [{self.id}]"


TRANSITIONS = (
    Transition(1, "configure", UNCONFIGURED, CONFIGURING, INACTIVE),
    Transition(2, "cleanup", INACTIVE, CLEANINGUP, UNCONFIGURED),
    Transition(3, "activate", INACTIVE, ACTIVATING, ACTIVE),
    Transition(4, "deactivate", ACTIVE, DEACTIVATING, INACTIVE),
    Transition(5, "shutdown", UNCONFIGURED, SHUTTINGDOWN, FINALIZED),
    Transition(6, "shutdown", INACTIVE, SHUTTINGDOWN, FINALIZED),
    Transition(7, "shutdown", ACTIVE, SHUTTINGDOWN, FINALIZED),
)


class LifecycleError(ValueError):
    """A transition that does not exist, or is not available in the current state."""


def available(state: int) -> List[Transition]:
    """The transitions a node in primary `state` accepts."""
    return [t for t in TRANSITIONS if t.start == state]


def resolve(state: int, transition_id: int = 0, label: str = "") -> Transition:
    """The transition a ChangeState request names (by label when given, else by id) from `state`."""
    for t in available(state):
        if (label and t.label == label) or (not label and t.id == transition_id):
            return t
    wanted = f"'{label}'" if label else f"id {transition_id}"
    offered = ", ".join(t.describe() for t in available(state)) or "none"
    raise LifecycleError(f"transition {wanted} is not available in state {STATE_LABELS.get(state, state)} "
                         f"(available: {offered})")


def outcome(transition: Transition, result: str, on_error_result: Optional[str] = None) -> int:
    """The primary state after `transition` whose hook returned `result` (on_error's result when
    the hook returned ERROR: success -> unconfigured, else finalized)."""
    if result == SUCCESS:
        return transition.goal
    if result == FAILURE:
        return transition.start
    return UNCONFIGURED if on_error_result == SUCCESS else FINALIZED
