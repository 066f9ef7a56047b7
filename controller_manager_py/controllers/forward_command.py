"""forward_command_controller/ForwardCommandController and position_controllers/JointGroupPositionController.

Subscribes `~/commands` (std_msgs/Float64MultiArray, one value per joint in `joints`
order) and writes them to `<joint>/<interface_name>`. Wrong-length or non-finite commands
are refused (counted, throttled warning); update() keeps the last good command and never
blocks. Activation and deactivation clear the command, so a stale one never applies.
"""
from __future__ import annotations

from ..controller_interface.base import (
    ControllerInterface,
    InterfaceConfiguration,
    interface_configuration_type,
)
from ..hardware_interface.types import CallbackReturn, State, return_type
from ..parameters import Param
from .command_slot import CommandSlot


def _non_empty(value):
    return None if value else "must list at least one joint"


class ForwardCommandController(ControllerInterface):
    PARAMS = (
        Param("joints", [""], "joints commanded, in the order of the command array", check=_non_empty),
        Param("interface_name", "position", "command interface written for every joint"),
    )

    def interface_name(self) -> str:
        return self.params["interface_name"]

    def on_configure(self, previous_state: State) -> CallbackReturn:
        joints = [j for j in self.params["joints"] if j]
        if not joints:
            self.get_logger().error(f"{self.name}: parameter 'joints' is empty")
            return CallbackReturn.ERROR
        self.joints = joints
        self.slot = CommandSlot(self.name, len(joints), self.get_logger())
        self.introspection.clear()  # (re)configure: the getters read the live attributes
        self.register_introspection("refused_commands", lambda: float(self.slot.refused))
        node = self.get_node()
        if node is not None and getattr(self, "_subscription", None) is None:
            from std_msgs.msg import Float64MultiArray
            self._subscription = node.create_subscription(Float64MultiArray, "~/commands", self.on_commands, 10)
        return CallbackReturn.SUCCESS

    def on_commands(self, msg) -> None:
        """Subscription callback (executor thread): check and hand over through the slot."""
        self.slot.offer(msg.data)

    def command_interface_configuration(self) -> InterfaceConfiguration:
        return InterfaceConfiguration(interface_configuration_type.INDIVIDUAL,
                                      [f"{j}/{self.interface_name()}" for j in self.joints])

    def on_activate(self, previous_state: State) -> CallbackReturn:
        self.slot.reset()
        return CallbackReturn.SUCCESS

    def on_deactivate(self, previous_state: State) -> CallbackReturn:
        self.slot.reset()
        return CallbackReturn.SUCCESS

    def on_cleanup(self, previous_state: State) -> CallbackReturn:
        node, sub = self.get_node(), getattr(self, "_subscription", None)
        if node is not None and sub is not None:
            node.destroy_subscription(sub)
            self._subscription = None
        return CallbackReturn.SUCCESS

    def update(self, time: float, period: float) -> return_type:
        command = self.slot.take()
        if command is not None:
            for handle, value in zip(self.command_interfaces, command):
                handle.value = value
        return return_type.OK


class JointGroupPositionController(ForwardCommandController):
    """ForwardCommandController with interface_name fixed to `position`."""

    PARAMS = (ForwardCommandController.PARAMS[0],)

    def interface_name(self) -> str:
        return "position"
