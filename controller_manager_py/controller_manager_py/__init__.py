"""controller_manager_py: ros2_control's controller manager, in Python (Jazzy semantics).

Rooms (as ros2_control's packages):
- `hardware_interface/`: component bases (SystemInterface, SensorInterface,
  ActuatorInterface; the contract is component.py's docstring), interface handles,
  the `<ros2_control>` description parser (urdf.py), the mock system
  (`mock_components/GenericSystem`). No rclpy.
- `controller_interface/`: ControllerInterface and ChainableControllerInterface (the
  contract is base.py's docstring). No rclpy.
- `controllers/`: the standard controllers (joint_state_broadcaster,
  position_controllers/JointGroupPositionController,
  joint_trajectory_controller/JointTrajectoryController, a chainable passthrough).
- `manager/`: resource manager (claiming, hardware lifecycle, joint limits), controller
  manager core (load/configure/switch, the read-update-write cycle), the loop thread,
  statistics, introspection entries, diagnostics roll-up. No rclpy.
- `ros/`: the `controller_manager` node (robot description, loop thread, spawning at
  start), ros2_control's services, pal_statistics registries (~/statistics,
  ~/introspection_data), ~/activity and /diagnostics.
- `ros2_control_node.py`, `spawner.py`: the executables.
- `plugins.py`: plugin discovery through entry points, groups
  `controller_manager_py.hardware` and `controller_manager_py.controllers`
  (entry name = the plugin string, e.g. `mock_components/GenericSystem`).
- `parameters.py`: the Param schema shared by nodes and controllers.

Installation, usage, parameters, plugins from other packages and the differences from
ros2_control: README.md in the package folder (next to package.xml and setup.py).
"""
