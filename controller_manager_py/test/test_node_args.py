"""What a controller's node takes from the manager's command line."""
from controller_manager_py.ros.node import forwarded_ros_args


def test_params_files_and_remaps_are_forwarded_but_not_node_renames_or_manager_parameters():
    argv = ["ros2_control_node", "--ros-args", "--params-file", "ctrl.yaml", "-p", "update_rate:=500",
            "-r", "__node:=cm2", "-r", "/joint_states:=/arm/joint_states", "--log-level", "warn", "--",
            "--params-file", "not_ros.yaml"]
    assert forwarded_ros_args(argv) == ["--params-file", "ctrl.yaml", "-r", "/joint_states:=/arm/joint_states",
                                        "--log-level", "warn"]


def test_check_params_is_taken_before_ros_args_only():
    from controller_manager_py.ros.node_main import _without_check_flag

    assert _without_check_flag(["node", "--check-params", "--ros-args", "-p", "a:=1"]) == \
        (["node", "--ros-args", "-p", "a:=1"], True)
    assert _without_check_flag(["node", "--ros-args", "-p", "a:=1", "--check-params"]) == \
        (["node", "--ros-args", "-p", "a:=1", "--check-params"], False)
    assert _without_check_flag(["node"]) == (["node"], False)


def test_arguments_outside_ros_args_are_named():
    from controller_manager_py.ros.node_main import _not_ros_arguments

    assert _not_ros_arguments(["--ros-args", "-p", "a:=1"]) == []
    assert _not_ros_arguments(["-p", "kp:=abc"]) == ["-p", "kp:=abc"]          # -p without --ros-args
    assert _not_ros_arguments(["--check-param", "--ros-args", "-p", "a:=1"]) == ["--check-param"]
    assert _not_ros_arguments(["--ros-args", "-p", "a:=1", "--", "extra"]) == ["extra"]


def test_an_rcl_error_is_one_line_with_the_name_it_is_about():
    from controller_manager_py.ros.node_main import one_line

    assert one_line(ValueError("topic name 'a b' is invalid: bad characters, at /project/src/rcl/x.c:73")) \
        == "topic name 'a b' is invalid: bad characters"
    assert one_line(ValueError("Invalid service name: bad characters:\n  'a b/list'\n    ^")) \
        == "Invalid service name: bad characters: 'a b/list'"
