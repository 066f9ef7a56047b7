"""Hardware room: component bases, handles, description parser, mock system (no rclpy).

Import from here: SystemInterface, ActuatorInterface, SensorInterface, HardwareInfo,
CallbackReturn, return_type, State, StateInterface, CommandInterface. The contract is
in component.py's docstrings.
"""
from .component import ActuatorInterface, HardwareComponentInterface, SensorInterface, SystemInterface
from .handle import NO_COMMAND, CommandInterface, Handle, StateInterface
from .types import (
    AsyncParams,
    CallbackReturn,
    ComponentInfo,
    HardwareInfo,
    InterfaceInfo,
    JointLimits,
    State,
    return_type,
)
from .urdf import DescriptionError, parse_control_resources

__all__ = [
    "ActuatorInterface", "AsyncParams", "CallbackReturn", "CommandInterface", "ComponentInfo",
    "DescriptionError", "Handle", "HardwareComponentInterface", "HardwareInfo", "InterfaceInfo",
    "JointLimits", "NO_COMMAND", "SensorInterface", "State", "StateInterface", "SystemInterface",
    "parse_control_resources", "return_type",
]
