"""Controller room: the controller base classes (the contract is in base.py)."""
from .base import (
    ChainableControllerInterface,
    ControllerInterface,
    InterfaceConfiguration,
    interface_configuration_type,
)

__all__ = ["ChainableControllerInterface", "ControllerInterface", "InterfaceConfiguration",
           "interface_configuration_type"]
