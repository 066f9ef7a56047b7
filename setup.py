"""ament_python package ball_balance: the application and controller_manager_py."""
import glob

from setuptools import find_packages, setup

PACKAGE = "ball_balance"

# `ros2 run ball_balance <name>`: the executables of docs/design.md section 4 plus tools.
EXECUTABLES = {
    "ball_tracker": "ball_balance.nodes.ball_tracker_node:main",
    "ball_balance_controller": "ball_balance.nodes.pid_controller_node:main",
    "ball_balance_mpc": "ball_balance.nodes.mpc_controller_node:main",
    "ball_balance_policy": "ball_balance.nodes.policy_node:main",
    "ball_balance_visualizer": "ball_balance.nodes.visualizer_node:main",
    "robot_state_publisher": "ball_balance.nodes.robot_state_publisher_node:main",
    "ros2_control_node": "controller_manager_py.ros2_control_node:main",
    "spawner": "controller_manager_py.spawner:main",
    "ros2py": "ball_balance.cli.main:main",
    "camera_snapshot": "ball_balance.nodes.camera_snapshot_node:main",
}

# controller_manager_py plugins (hardware components and controllers), by plugin string.
CMPY_HARDWARE = {
    "mock_components/GenericSystem": "controller_manager_py.hardware_interface.mock_components:GenericSystem",
    "ball_balance/MujocoSystem": "ball_balance.hardware.mujoco_system:MujocoSystem",
}
CMPY_CONTROLLERS = {
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
    "ball_balance_controllers/BallBalanceController":
        "ball_balance.controllers.ball_balance_controller:BallBalanceController",
}

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=["ball_balance", "ball_balance.*",
                                    "controller_manager_py", "controller_manager_py.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", sorted(f for f in glob.glob("config/*") if "." in f)),
        (f"share/{PACKAGE}/config/policies", sorted(glob.glob("config/policies/*"))),
        (f"share/{PACKAGE}/config/paths", sorted(glob.glob("config/paths/*"))),
        (f"share/{PACKAGE}/scripts", sorted(glob.glob("scripts/*.sh"))),
        (f"share/{PACKAGE}/scripts/lib", sorted(glob.glob("scripts/lib/*.sh"))),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="ball_balance team",
    maintainer_email="team@ball-balance.invalid",
    description="Balance a ball on a plate held by a UR arm (ROS 2 Jazzy, rclpy).",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [f"{name} = {target}" for name, target in EXECUTABLES.items()],
        # controller_manager_py's pluginlib: entry name = the plugin string (see plugins.py)
        "controller_manager_py.hardware": [f"{n} = {t}" for n, t in CMPY_HARDWARE.items()],
        "controller_manager_py.controllers": [f"{n} = {t}" for n, t in CMPY_CONTROLLERS.items()],
    },
)
