"""ament_python package controller_manager_py: ros2_control's controller manager in Python."""
from setuptools import find_packages, setup

PACKAGE = "controller_manager_py"

# `ros2 run controller_manager_py <name>`
EXECUTABLES = {
    "ros2_control_node": "controller_manager_py.ros2_control_node:main",
    "spawner": "controller_manager_py.spawner:main",
}

# The plugins this package ships, by plugin string (entry name = plugin string, see plugins.py).
# Another package registers its own hardware and controllers under the same two groups.
HARDWARE = {
    "mock_components/GenericSystem": "controller_manager_py.hardware_interface.mock_components:GenericSystem",
}
CONTROLLERS = {
    "joint_state_broadcaster/JointStateBroadcaster":
        "controller_manager_py.controllers.joint_state_broadcaster:JointStateBroadcaster",
    "position_controllers/JointGroupPositionController":
        "controller_manager_py.controllers.forward_command:JointGroupPositionController",
    "forward_command_controller/ForwardCommandController":
        "controller_manager_py.controllers.forward_command:ForwardCommandController",
    "joint_trajectory_controller/JointTrajectoryController":
        "controller_manager_py.controllers.joint_trajectory:JointTrajectoryController",
    "onnx_policy_controller/OnnxPolicyController":
        "controller_manager_py.controllers.onnx_policy:OnnxPolicyController",
    "chained_controllers/PassthroughController":
        "controller_manager_py.controllers.passthrough:PassthroughController",
    "ur_controllers/ScaledJointTrajectoryController":
        "controller_manager_py.controllers.joint_trajectory:ScaledJointTrajectoryController",
}

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml", "README.md"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="controller_manager_py maintainers",
    maintainer_email="team@ball-balance.invalid",
    description="ros2_control's controller manager in Python (Jazzy semantics), plugins through entry points.",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [f"{name} = {target}" for name, target in EXECUTABLES.items()],
        "controller_manager_py.hardware": [f"{n} = {t}" for n, t in HARDWARE.items()],
        "controller_manager_py.controllers": [f"{n} = {t}" for n, t in CONTROLLERS.items()],
    },
)
