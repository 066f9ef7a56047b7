"""ros2py's message helpers: YAML like ros2 topic echo, YAML to message with clear errors."""
import pytest

from ball_balance.cli.errors import CliError
from ball_balance.cli.messages import (
    echo_text,
    get_field,
    get_interface,
    message_to_yaml,
    parse_yaml_values,
    set_message_fields,
    type_name_of,
)
from ball_balance.cli.topic import bandwidth_text, hz_statistics


def test_ball_state_prints_as_ros2_topic_echo_does():
    cls = get_interface("ball_tracker_msgs/msg/BallState")
    msg = cls(x=0.125, ball_found=True, markers_found=3)
    msg.header.frame_id = "plate_center"
    assert message_to_yaml(msg) == (
        "header:\n  stamp:\n    sec: 0\n    nanosec: 0\n  frame_id: plate_center\n"
        "x: 0.125\ny: 0.0\nvx: 0.0\nvy: 0.0\nball_found: true\ntracking_valid: false\n"
        "markers_found: 3\npixel_u: 0.0\npixel_v: 0.0\n")


def test_arrays_are_block_lists_and_truncated():
    msg = get_interface("sensor_msgs/JointState")(name=["a", "b"], position=[1.0, 2.5])
    text = message_to_yaml(msg)
    assert "name:\n- a\n- b\nposition:\n- 1.0\n- 2.5\nvelocity: []\n" in text
    long = get_interface("std_msgs/msg/Float64MultiArray")(data=[float(i) for i in range(5)])
    assert message_to_yaml(long, truncate_length=2).endswith("data:\n- 0.0\n- 1.0\n- '...'\n")


def test_byte_fields_print_as_ros2_topic_echo_does():
    # rosidl_runtime_py (Jazzy) convert.py: bytes -> ''.join(chr(b)), dumped by yaml.dump; never `!!binary`
    status = get_interface("diagnostic_msgs/msg/DiagnosticStatus")(
        level=b"\x02", name="camera", message="stale", hardware_id="cam0")
    status.values = [get_interface("diagnostic_msgs/msg/KeyValue")(key="age", value="3.5")]
    expected = ('level: "\\x02"\nname: camera\nmessage: stale\nhardware_id: cam0\n'
                "values:\n- key: age\n  value: '3.5'\n")
    assert message_to_yaml(status) == expected
    array = get_interface("diagnostic_msgs/msg/DiagnosticArray")(status=[status])
    assert message_to_yaml(array).endswith("status:\n- level: \"\\x02\"\n  name: camera\n" + "".join(
        f"  {line}\n" for line in expected.splitlines()[2:]))
    assert message_to_yaml(get_interface("diagnostic_msgs/msg/DiagnosticStatus")(level=b"A")).startswith("level: A\n")
    # `--field level`: ros2cli prints a field that is not a message with print(), i.e. str()
    assert echo_text(status.level) == "b'\\x02'\n"
    assert echo_text(status) == expected


def test_byte_and_uint8_arrays_print_as_ros2_topic_echo_does():
    # byte[]: rclpy gives a list of 1-byte bytes -> one-character strings; uint8[]: numbers
    data = [b"\x01", b"A", b"\xff"]
    byte_array = get_interface("std_msgs/msg/ByteMultiArray")(data=data)
    assert message_to_yaml(byte_array) == 'layout:\n  dim: []\n  data_offset: 0\ndata:\n- "\\x01"\n- A\n- \xff\n'
    assert message_to_yaml(byte_array, truncate_length=1).endswith('data:\n- "\\x01"\n- \'...\'\n')
    assert message_to_yaml(byte_array, no_arr=True).endswith("data: '<sequence type: octet, length: 3>'\n")
    uint8_array = get_interface("std_msgs/msg/UInt8MultiArray")(data=[1, 65, 255])
    assert message_to_yaml(uint8_array).endswith("data:\n- 1\n- 65\n- 255\n")
    assert echo_text(byte_array.data) == "[b'\\x01', b'A', b'\\xff']\n"


def test_no_arr_names_the_declared_array_type_as_ros2cli():
    joints = get_interface("sensor_msgs/msg/JointState")(name=["a"], position=[1.0, 2.0])
    assert message_to_yaml(joints, no_arr=True).endswith(
        "name: '<sequence type: string, length: 1>'\nposition: '<sequence type: double, length: 2>'\n"
        "velocity: '<sequence type: double, length: 0>'\neffort: '<sequence type: double, length: 0>'\n")
    imu = get_interface("sensor_msgs/msg/Imu")()
    assert "orientation_covariance: '<array type: double[9]>'\n" in message_to_yaml(imu, no_arr=True)


def test_field_selection_and_scalars():
    msg = get_interface("geometry_msgs/msg/TransformStamped")()
    msg.transform.translation.x = 1.5
    assert message_to_yaml(get_field(msg, "transform.translation.x")) == "1.5\n"
    with pytest.raises(CliError, match="invalid field 'transform.nope'.*has no field 'nope'"):
        get_field(msg, "transform.nope")


def test_yaml_values_fill_nested_messages_and_sequences():
    msg = set_message_fields(get_interface("tf2_msgs/msg/TFMessage")(), parse_yaml_values(
        "{transforms: [{header: {frame_id: world}, child_frame_id: plate, transform: {translation: {x: 1}}}]}"))
    (t,) = msg.transforms
    assert (t.header.frame_id, t.child_frame_id, t.transform.translation.x) == ("world", "plate", 1.0)
    stamped = set_message_fields(get_interface("std_msgs/msg/Header")(), {"stamp": "now"}, now_ns=1_500_000_000)
    assert (stamped.stamp.sec, stamped.stamp.nanosec) == (1, 500_000_000)
    assert type_name_of(t) == "geometry_msgs/msg/TransformStamped"


@pytest.mark.parametrize("type_name, values, error", [
    ("std_msgs/msg/String", "{dta: hi}", "has no field 'dta'"),
    ("std_msgs/msg/Int32", "{data: hello}", r"field 'data' \(int32\): expected an integer"),
    ("std_msgs/msg/UInt8", "{data: 300}", r"300 is outside \[0, 255\]"),
    ("std_msgs/msg/Bool", "{data: 1}", "expected true or false"),
    ("sensor_msgs/msg/JointState", "{position: 3}", "expected a list"),
    ("std_msgs/msg/String", "[1, 2]", "must be a mapping"),
])
def test_wrong_values_name_the_field(type_name, values, error):
    with pytest.raises(CliError, match=error):
        set_message_fields(get_interface(type_name)(), parse_yaml_values(values))


def test_a_number_yaml_reads_as_a_string_fills_a_float_field():
    # YAML 1.1 reads 1e308 (no dot) as a string; ros2 topic pub takes it as a number
    message = set_message_fields(get_interface("std_msgs/msg/Float64")(), parse_yaml_values("{data: 1e308}"))
    assert message.data == 1e308
    with pytest.raises(CliError, match=r"field 'data' \(double\): expected a number, got 'abc'"):
        set_message_fields(get_interface("std_msgs/msg/Float64")(), parse_yaml_values("{data: abc}"))


def test_bad_yaml_and_unknown_types_are_one_line_errors():
    with pytest.raises(CliError, match=r"not valid YAML: expected .* at line 1, column 14") as bad_yaml:
        parse_yaml_values("{data: [hello")
    assert "\n" not in str(bad_yaml.value)
    with pytest.raises(CliError, match="no interface package 'nopkg'"):
        get_interface("nopkg/msg/Thing")
    with pytest.raises(CliError, match="package 'std_msgs' has no msg 'Strin'"):
        get_interface("std_msgs/msg/Strin")
    with pytest.raises(CliError, match="not a valid interface type name"):
        get_interface("String")


def test_bandwidth_lines_use_the_rates_unit_for_every_figure_as_ros2_topic_bw():
    assert bandwidth_text(500.0, 10, 50.0, 48, 52) == (
        "500 B/s from 10 messages\n\tMessage size mean: 50 B min: 48 B max: 52 B")
    assert bandwidth_text(1600.5, 32, 50.0, 50, 50) == (
        "1.60 KB/s from 32 messages\n\tMessage size mean: 0.05 KB min: 0.05 KB max: 0.05 KB")
    assert bandwidth_text(27.65e6, 30, 921654, 921654, 921654).startswith(
        "27.65 MB/s from 30 messages\n\tMessage size mean: 0.92 MB")


def test_hz_statistics_match_the_definition():
    rate, lo, hi, std = hz_statistics([0.1, 0.1, 0.1, 0.1])
    assert rate == pytest.approx(10.0) and lo == hi == pytest.approx(0.1) and std == pytest.approx(0.0)
    rate, lo, hi, std = hz_statistics([0.1, 0.3])
    assert rate == pytest.approx(5.0) and (lo, hi) == (0.1, 0.3) and std == pytest.approx(0.1)
