"""forward_command_controller/ForwardCommandController and position_controllers/JointGroupPositionController.

Subscribes `~/commands` (std_msgs/Float64MultiArray, one value per joint in `joints`
order) and writes them to `<joint>/<interface_name>`. Wrong-length or non-finite commands
are refused (counted, throttled warning); update() keeps the last good command and never
blocks. Activation and deactivation clear the command, so a stale one never applies.

`command_ramp: true` (ours; ros2_controllers writes commands as they come, the default)
writes each new command as a straight line from the value last written, reached in the update
before the next command is expected: commands sent at a balance controller's 60 Hz then reach
a stiff simulated servo as a ramp instead of a staircase (command_ramp.py says why that
matters). How far apart commands come is measured, at most `command_ramp_max_s`.
"""
from __future__ import annotations

import numpy as np

from ..controller_interface.base import (
    ControllerInterface,
    InterfaceConfiguration,
    interface_configuration_type,
)
from ..hardware_interface.types import CallbackReturn, State, return_type
from ..parameters import Param
from .command_ramp import CommandIntervalEstimate, CommandRamp
from .command_slot import CommandSlot


def _non_empty(value):
    return None if value else "must list at least one joint"


_RAMP_PARAMS = (
    Param("command_ramp", False, "write each new command as a ramp from the value last written, reached when "
          "the next command is expected (false: as it comes, as ros2_controllers does)", read_only=True),
    Param("command_ramp_max_s", 0.05, "longest ramp: commands further apart than this are reached after it",
          "s", 0.001, 1.0, read_only=True),
)


class ForwardCommandController(ControllerInterface):
    PARAMS = (
        Param("joints", [""], "joints commanded, in the order of the command array", check=_non_empty,
              user_facing=True),
        Param("interface_name", "position", "command interface written for every joint", user_facing=True),
        *_RAMP_PARAMS,
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
        ramped = self.params["command_ramp"]
        self._ramp = CommandRamp(len(joints)) if ramped else None
        self._intervals = CommandIntervalEstimate(self.params["command_ramp_max_s"]) if ramped else None
        self._written = np.zeros(len(joints))
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
        self._reset()
        return CallbackReturn.SUCCESS

    def on_deactivate(self, previous_state: State) -> CallbackReturn:
        self._reset()
        return CallbackReturn.SUCCESS

    def _reset(self) -> None:
        self.slot.reset()
        if self._intervals is not None:
            self._intervals.reset()

    def on_cleanup(self, previous_state: State) -> CallbackReturn:
        node, sub = self.get_node(), getattr(self, "_subscription", None)
        if node is not None and sub is not None:
            node.destroy_subscription(sub)
            self._subscription = None
        return CallbackReturn.SUCCESS

    def update(self, time: float, period: float) -> return_type:
        command = self.slot.take()
        if command is None:
            return return_type.OK
        if self._ramp is not None:
            if command is not self._ramp.target:   # a new one: ramp on from what was written last
                for i, handle in enumerate(self.command_interfaces):
                    self._written[i] = handle.value
                self._ramp.retarget(command, self._written, time, period, self._intervals.arrived(time))
            command = self._ramp.at(time)
        for handle, value in zip(self.command_interfaces, command):
            handle.value = float(value)
        return return_type.OK


class JointGroupPositionController(ForwardCommandController):
    """ForwardCommandController with interface_name fixed to `position`."""

    PARAMS = (ForwardCommandController.PARAMS[0], *_RAMP_PARAMS)

    def interface_name(self) -> str:
        return "position"
