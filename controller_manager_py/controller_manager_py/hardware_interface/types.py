"""Return codes, lifecycle states and the parsed description of a hardware component.

No rclpy import: these types are shared by the manager, components and pure tests.
The lifecycle ids are those of lifecycle_msgs/State (so they go on the wire unchanged).
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Dict, List, Optional


class return_type(enum.IntEnum):  # noqa: N801 - the ros2_control name
    """Result of read()/write()/update(): OK, or ERROR (the manager reacts, see the loop)."""

    OK = 0
    ERROR = 1
    DEACTIVATE = 2


class CallbackReturn(enum.IntEnum):
    """Result of a lifecycle hook: SUCCESS moves on, FAILURE stays, ERROR goes to on_error."""

    SUCCESS = 0
    FAILURE = 1
    ERROR = 2


class State(enum.IntEnum):
    """Primary lifecycle states (ids of lifecycle_msgs/State)."""

    UNKNOWN = 0
    UNCONFIGURED = 1
    INACTIVE = 2
    ACTIVE = 3
    FINALIZED = 4

    @property
    def label(self) -> str:
        return self.name.lower()


@dataclass
class InterfaceInfo:
    """One `<command_interface>`/`<state_interface>`: name, limits and initial value."""

    name: str
    min: Optional[float] = None
    max: Optional[float] = None
    initial_value: Optional[float] = None
    data_type: str = "double"
    parameters: Dict[str, str] = field(default_factory=dict)


@dataclass
class ComponentInfo:
    """One `<joint>`, `<sensor>` or `<gpio>` of a hardware block."""

    name: str
    type: str  # "joint" | "sensor" | "gpio"
    command_interfaces: List[InterfaceInfo] = field(default_factory=list)
    state_interfaces: List[InterfaceInfo] = field(default_factory=list)
    parameters: Dict[str, str] = field(default_factory=dict)


@dataclass
class AsyncParams:
    """`<properties><async .../>`: how an is_async component's thread runs."""

    thread_priority: int = 50
    affinity: List[int] = field(default_factory=list)
    scheduling_policy: str = "synchronized"  # or "detached"
    print_warnings: bool = True


@dataclass
class JointLimits:
    """Limits of one joint from the URDF `<limit>` and the ros2_control min/max params
    (position rad or m, velocity per s, acceleration per s^2; inf: no limit)."""

    min_position: float = float("-inf")
    max_position: float = float("inf")
    max_velocity: float = float("inf")
    max_effort: float = float("inf")
    max_acceleration: float = float("inf")
    disabled: frozenset = frozenset()
    """Command interfaces excluded by `<limits enable="false"/>` (on the joint: all of them)."""

    def enforced(self, interface: str) -> bool:
        return "*" not in self.disabled and interface not in self.disabled

    @property
    def has_position_limits(self) -> bool:
        return self.min_position > float("-inf") or self.max_position < float("inf")

    @property
    def has_velocity_limits(self) -> bool:
        return self.max_velocity < float("inf")

    @property
    def has_acceleration_limits(self) -> bool:
        return self.max_acceleration < float("inf")


@dataclass
class HardwareInfo:
    """Everything the robot description says about one `<ros2_control>` block.

    name: the block's `name` attribute; type: "system" | "sensor" | "actuator";
    hardware_plugin_name: the `<plugin>` text (entry-point name); hardware_parameters: the
    `<param>` children of `<hardware>`; joints/sensors/gpios: the components;
    is_async/rw_rate (Hz, 0 = the manager's rate)/async_params: how read/write are run;
    limits: per-joint limits (URDF `<limit>` merged with min/max params); original_xml:
    the block's text.
    """

    name: str
    type: str
    hardware_plugin_name: str
    hardware_parameters: Dict[str, str] = field(default_factory=dict)
    joints: List[ComponentInfo] = field(default_factory=list)
    sensors: List[ComponentInfo] = field(default_factory=list)
    gpios: List[ComponentInfo] = field(default_factory=list)
    is_async: bool = False
    rw_rate: int = 0
    async_params: AsyncParams = field(default_factory=AsyncParams)
    limits: Dict[str, JointLimits] = field(default_factory=dict)
    original_xml: str = ""

    @property
    def plugin(self) -> str:
        return self.hardware_plugin_name

    def components(self) -> List[ComponentInfo]:
        return [*self.joints, *self.sensors, *self.gpios]
