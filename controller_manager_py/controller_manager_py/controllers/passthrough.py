"""chained_controllers/PassthroughController: a chainable controller (reference interfaces).

Exports `<name>/<joint>/<interface_name>` reference interfaces and copies them to the
joints' command interfaces. Unchained it takes `~/commands` like a forward controller;
chained, a preceding controller writes the references (the manager updates it first).
"""
from __future__ import annotations

from ..controller_interface.base import ChainableControllerInterface
from ..hardware_interface.types import CallbackReturn, State, return_type
from .forward_command import ForwardCommandController


class PassthroughController(ChainableControllerInterface):
    PARAMS = ForwardCommandController.PARAMS
    on_configure = ForwardCommandController.on_configure
    on_commands = ForwardCommandController.on_commands
    on_cleanup = ForwardCommandController.on_cleanup
    command_interface_configuration = ForwardCommandController.command_interface_configuration

    def interface_name(self) -> str:
        return self.params["interface_name"]

    def on_export_reference_interfaces(self):
        return [f"{j}/{self.interface_name()}" for j in self.joints]

    def on_activate(self, previous_state: State) -> CallbackReturn:
        self.slot.reset()
        for ref in self.reference_interfaces:
            ref.value = float("nan")
        return CallbackReturn.SUCCESS

    on_deactivate = on_activate

    def update_reference_from_subscribers(self, time: float, period: float) -> return_type:
        command = self.slot.take()
        if command is not None:
            for ref, value in zip(self.reference_interfaces, command):
                ref.value = value
        return return_type.OK

    def update_and_write_commands(self, time: float, period: float) -> return_type:
        for ref, handle in zip(self.reference_interfaces, self.command_interfaces):
            value = ref.value
            if value == value:
                handle.value = value
        return return_type.OK
