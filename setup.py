"""ament_python package ball_balance: the application (controller_manager_py is its own package)."""
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
    "ball_balance_foxglove": "ball_balance.nodes.foxglove_node:main",
    "ball_balance_live_view": "ball_balance.nodes.live_view_node:main",
    "robot_state_publisher": "ball_balance.nodes.robot_state_publisher_node:main",
    "robot_manager": "ball_balance.nodes.robot_manager_node:main",
    "ros2py": "ball_balance.cli.main:main",
    "camera_snapshot": "ball_balance.nodes.camera_snapshot_node:main",
}

# Our plugins for controller_manager_py (hardware components and controllers), by plugin string.
# controller_manager_py's own (mock_components/GenericSystem, the standard controllers) are
# registered by its own setup.py, under the same entry-point groups.
CMPY_HARDWARE = {
    "ball_balance/MujocoSystem": "ball_balance.hardware.mujoco_system:MujocoSystem",
}
CMPY_CONTROLLERS = {
    "ball_balance_controllers/BallBalanceController":
        "ball_balance.controllers.ball_balance_controller:BallBalanceController",
}

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=["ball_balance", "ball_balance.*"]),
    package_data={"ball_balance.live_view": ["static/*"]},  # the live view's page: served from the package
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
