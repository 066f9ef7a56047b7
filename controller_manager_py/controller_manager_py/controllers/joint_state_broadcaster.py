"""joint_state_broadcaster/JointStateBroadcaster: joint states -> /joint_states.

Parameters: `joints` (empty: every joint with a position/velocity/effort state; else these,
in this order) and `interfaces` (default position, velocity, effort: those a joint has are
published); `use_local_topics` publishes on
`~/joint_states` instead. The message is built once at activation; update() only copies
the values into its arrays and publishes (a joint without an interface reports NaN, as
ros2_control does). The stamp is the manager's time (simulated when hardware owns the clock).
"""
from __future__ import annotations

from ..controller_interface.base import (
    ControllerInterface,
    InterfaceConfiguration,
    interface_configuration_type,
)
from ..hardware_interface.types import CallbackReturn, State, return_type
from ..parameters import Param

JOINT_STATE_INTERFACES = ("position", "velocity", "effort")


class JointStateBroadcaster(ControllerInterface):
    PARAMS = (
        Param("joints", [""], "joints to publish; empty = all joints with position/velocity/effort", user_facing=True),
        Param("interfaces", list(JOINT_STATE_INTERFACES), "state interfaces published", user_facing=True),
        Param("use_local_topics", False, "publish on ~/joint_states instead of /joint_states", user_facing=True),
    )

    def on_configure(self, previous_state: State) -> CallbackReturn:
        from sensor_msgs.msg import JointState

        self.joints = [j for j in self.params["joints"] if j]
        self.interfaces = [i for i in self.params["interfaces"] if i in JOINT_STATE_INTERFACES]
        self.msg = JointState()
        self._publisher = None
        node = self.get_node()
        if node is not None:
            topic = "~/joint_states" if self.params["use_local_topics"] else "/joint_states"
            self._publisher = node.create_publisher(JointState, topic, 10)
        return CallbackReturn.SUCCESS

    def state_interface_configuration(self) -> InterfaceConfiguration:
        return InterfaceConfiguration(interface_configuration_type.ALL)  # filtered at activation

    def on_activate(self, previous_state: State) -> CallbackReturn:
        handles = [h for h in self.state_interfaces if h.interface_name in self.interfaces
                   and (not self.joints or h.prefix_name in self.joints)]
        present = {h.prefix_name for h in handles}
        missing = [j for j in self.joints if j not in present]
        if missing:
            self.get_logger().error(f"{self.name}: joints {missing} have none of the interfaces {self.interfaces}")
            return CallbackReturn.ERROR
        names = [j for j in self.joints] if self.joints else list(dict.fromkeys(h.prefix_name for h in handles))
        nan = float("nan")
        msg = self.msg
        msg.name = names
        # per interface: (message array, [(index, handle)]) resolved once
        self._copies = []
        for itf in JOINT_STATE_INTERFACES:
            pairs = [(names.index(h.prefix_name), h) for h in handles if h.interface_name == itf]
            setattr(msg, itf, [nan] * len(names) if pairs else [])
            if pairs:
                self._copies.append((getattr(msg, itf), pairs))
        return CallbackReturn.SUCCESS

    def on_cleanup(self, previous_state: State) -> CallbackReturn:
        if self._publisher is not None:
            self.get_node().destroy_publisher(self._publisher)
            self._publisher = None
        return CallbackReturn.SUCCESS

    def update(self, time: float, period: float) -> return_type:
        msg = self.msg
        for array, pairs in self._copies:
            for index, handle in pairs:
                array[index] = handle.value
        seconds = int(time)
        msg.header.stamp.sec = seconds
        msg.header.stamp.nanosec = int((time - seconds) * 1e9)
        if self._publisher is not None:
            self._publisher.publish(msg)
        return return_type.OK
