"""Parameter files checked before a node starts, and unknown parameter names named."""
import pytest

from controller_manager_py.parameters import (
    Param,
    ParameterError,
    describe_unknown,
    renamed_names,
    unknown_parameter_names,
    validate,
)
from controller_manager_py.ros.params_files import ParamsFileError, check_params_files, params_files_in


def test_only_params_files_inside_ros_args_are_checked():
    argv = ["--params-file", "a.yaml", "--ros-args", "-p", "x:=1", "--params-file", "b.yaml", "--",
            "--params-file", "c.yaml", "--ros-args", "--params-file", "d.yaml"]
    assert params_files_in(argv) == ["b.yaml", "d.yaml"]


@pytest.mark.parametrize("text, error", [
    ("node:\n  ros__parameters:\n    gain: [1\n", "not valid YAML"),
    ("- a list\n", "must map node names"),
])
def test_a_malformed_params_file_is_one_line_naming_the_file(tmp_path, text, error):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ParamsFileError, match=error) as raised:
        check_params_files(["--ros-args", "--params-file", str(path)])
    assert "\n" not in str(raised.value) and str(path) in str(raised.value)


def test_a_missing_params_file_names_the_file(tmp_path):
    with pytest.raises(ParamsFileError, match="cannot read parameter file .*nope.yaml"):
        check_params_files(["--ros-args", "--params-file", str(tmp_path / "nope.yaml")])


def test_unknown_parameter_names_suggest_the_closest_declared_one():
    declared = ["kp", "kd", "ki", "max_tilt_rad", "use_sim_time"]
    unknown = unknown_parameter_names(["kp", "kp_typo", "max_tilt", "zzz"], declared)
    assert unknown == ["kp_typo", "max_tilt", "zzz"]
    assert describe_unknown(unknown, declared) == \
        "kp_typo (did you mean kp?), max_tilt (did you mean max_tilt_rad?), zzz"


def test_a_former_name_is_reported_with_its_new_name():
    schema = [Param("loss_hold_s", 0.3, formerly=("grace_s",)), Param("kp", 2.0)]
    assert renamed_names(schema) == {"grace_s": "loss_hold_s"}
    assert describe_unknown(["grace_s", "kp_typo"], ["loss_hold_s", "kp"], renamed_names(schema)) == \
        "grace_s (renamed loss_hold_s), kp_typo (did you mean kp?)"
    with pytest.raises(ParameterError, match=r"grace_s \(renamed loss_hold_s\)"):
        validate(schema, {"grace_s": 0.5})


def test_a_node_given_a_former_name_names_the_new_one():
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from controller_manager_py.parameters import declare_parameters, report_unknown_parameters

    context = Context()
    rclpy.init(context=context, args=["--ros-args", "--disable-external-lib-logs"])
    try:
        node = Node("renamed_test", context=context, parameter_overrides=[
            Parameter("grace_s", value=0.5), Parameter("unknown_parameters", value="error")])
        declare_parameters(node, [Param("loss_hold_s", 0.3, formerly=("grace_s",))])
        with pytest.raises(ParameterError, match=r"/renamed_test: grace_s \(renamed loss_hold_s\)"):
            report_unknown_parameters(node)
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_an_array_set_at_run_time_is_accepted_as_a_list():
    # rclpy hands a double array set through set_parameters as array.array('d')
    import array

    from controller_manager_py.parameters import Param

    centre = Param("centre_m", [0.0, 0.0], "a point")
    assert centre.validate(array.array("d", [0.02, -0.01])) == (0.02, -0.01)


def test_a_value_of_the_wrong_kind_is_named_in_the_schemas_words():
    topics = Param("topics", ["/a"], "topics")
    with pytest.raises(ParameterError, match=r"'topics' = \[\] has no type in ROS"):
        topics.validate(None)   # rcl's value for `-p topics:=[]`
    with pytest.raises(ParameterError, match="'rate_hz' = 'fast' must be of type float"):
        Param("rate_hz", 1.0, "rate").validate("fast")
    assert topics.validate(["/b"]) == ("/b",)
