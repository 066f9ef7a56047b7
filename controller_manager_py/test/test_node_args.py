"""What a controller's node takes from the manager's command line."""
from controller_manager_py.ros.node import forwarded_ros_args


def test_params_files_and_remaps_are_forwarded_but_not_node_renames_or_manager_parameters():
    argv = ["ros2_control_node", "--ros-args", "--params-file", "ctrl.yaml", "-p", "update_rate:=500",
            "-r", "__node:=cm2", "-r", "/joint_states:=/arm/joint_states", "--log-level", "warn", "--",
            "--params-file", "not_ros.yaml"]
    assert forwarded_ros_args(argv) == ["--params-file", "ctrl.yaml", "-r", "/joint_states:=/arm/joint_states",
                                        "--log-level", "warn"]
