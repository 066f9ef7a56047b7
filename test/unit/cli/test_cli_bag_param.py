"""ros2py helpers without DDS: MCAP schema text, parameter files and values."""
import pytest

from ball_balance.cli.bag_format import SEPARATOR, message_definition, nested_types
from ball_balance.cli.errors import CliError
from ball_balance.cli.param import flatten, nest, parameters_from_file, python_to_value, value_to_python


def test_schema_text_is_the_msg_file_followed_by_each_nested_type_once():
    text = message_definition("ball_tracker_msgs/msg/BallState")
    sections = text.split(f"\n{SEPARATOR}\n")
    assert "float64 pixel_u" in sections[0]
    assert [s.splitlines()[0] for s in sections[1:]] == ["MSG: std_msgs/Header", "MSG: builtin_interfaces/Time"]
    tf_text = message_definition("tf2_msgs/msg/TFMessage")
    assert tf_text.count("MSG: builtin_interfaces/Time") == 1 and "MSG: geometry_msgs/Quaternion" in tf_text


def test_nested_types_skip_primitives_constants_and_resolve_short_names():
    text = "int32 STRICT=2\nstring<=10 name\nfloat64[3] xyz\nHeader header\nPoint[] points # pts\npkg2/Other o\n"
    assert nested_types(text, "pkg") == ["std_msgs/Header", "pkg/Point", "pkg2/Other"]


def test_parameter_values_round_trip_and_refuse_mixed_lists():
    for value in (True, 3, 0.5, "ball", [1, 2], [0.5, 1], ["a", "b"], [True]):
        expected = [float(v) for v in value] if value == [0.5, 1] else value
        assert value_to_python(python_to_value(value)) == expected
    with pytest.raises(CliError, match="one type"):
        python_to_value([1, "a"], "mixed")
    with pytest.raises(CliError, match="cannot set"):
        python_to_value({"a": 1}, "nested")


def test_parameter_files_nest_and_flatten():
    flat = {"gain": 0.5, "limits.max_tilt": 3, "limits.min_tilt": -3}
    assert nest(flat) == {"gain": 0.5, "limits": {"max_tilt": 3, "min_tilt": -3}}
    assert flatten(nest(flat)) == flat
    text = "/**:\n  ros__parameters:\n    use_sim_time: true\ntracker:\n  ros__parameters:\n    gain: 2.0\n"
    assert parameters_from_file(text, "/tracker") == {"use_sim_time": True, "gain": 2.0}


@pytest.mark.parametrize("text, error", [
    ("tracker:\n  ros__parameters:\n    gain: [1\n", "not valid YAML"),
    ("- just a list\n", "at the top level"),
    ("tracker:\n  gain: 1\n", "no 'ros__parameters' mapping"),
    ("other:\n  ros__parameters:\n    gain: 1\n", "no parameters for node '/tracker'"),
])
def test_malformed_parameter_files_are_one_line_errors(text, error):
    with pytest.raises(CliError, match=error) as raised:
        parameters_from_file(text, "/tracker", "bad.yaml")
    assert "\n" not in str(raised.value) and "bad.yaml" in str(raised.value)


def test_interface_show_expands_nested_types_with_tabs():
    from ball_balance.cli.interface import interface_text

    text = interface_text("ball_tracker_msgs/msg/BallState")
    assert "std_msgs/Header header" in text and "\n\tbuiltin_interfaces/Time stamp\n" in text
    assert "\n\t\tint32 sec\n" in text and "\nfloat64 pixel_v" in text
    service = interface_text("controller_manager_msgs/srv/SwitchController")
    assert "\n---\n" in service and "\n\tint32 sec\n" in service
    with pytest.raises(CliError, match="foo/msg/Bar"):
        interface_text("foo/msg/Bar")


class _Endpoint:
    def __init__(self, reliability: str, durability: str):
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        self.qos_profile = QoSProfile(depth=5, reliability=ReliabilityPolicy[reliability],
                                      durability=DurabilityPolicy[durability])


def test_the_recorder_matches_every_publisher_and_rematches_when_one_joins():
    from ball_balance.cli.bag import matching_policies

    reliable, latched = _Endpoint("RELIABLE", "VOLATILE"), _Endpoint("RELIABLE", "TRANSIENT_LOCAL")
    assert matching_policies([reliable]) == ("reliable", "volatile")
    assert matching_policies([latched]) == ("reliable", "transient_local")
    assert matching_policies([latched, reliable]) == ("reliable", "volatile")
    assert matching_policies([reliable, _Endpoint("BEST_EFFORT", "VOLATILE")]) == ("best_effort", "volatile")
    assert matching_policies([]) == ("best_effort", "volatile")


def test_recorded_qos_profiles_are_jazzy_names_and_play_back_as_publishers():
    from ball_balance.cli.bag import offered_profiles
    from ball_balance.cli.bag_format import dump_yaml, parse_offered_qos
    from ball_balance.cli.bag_play import publisher_qos

    class Info:
        qos_profile = _Endpoint("BEST_EFFORT", "VOLATILE").qos_profile

    (profile,) = offered_profiles([Info()])
    assert (profile["history"], profile["depth"], profile["reliability"], profile["durability"]) == \
        ("keep_last", 5, "best_effort", "volatile")
    assert profile["deadline"] == {"sec": 9223372036, "nsec": 854775807}  # unset: infinite
    assert parse_offered_qos(dump_yaml([profile])) == [profile]
    qos = publisher_qos([profile])
    assert (qos.reliability.name, qos.durability.name, qos.depth) == ("BEST_EFFORT", "VOLATILE", 5)
    # metadata version 8 wrote the policies as integers
    old = publisher_qos(parse_offered_qos("- history: 3\n  depth: 0\n  reliability: 1\n  durability: 1\n"))
    assert (old.reliability.name, old.durability.name, old.depth) == ("RELIABLE", "TRANSIENT_LOCAL", 10)


def test_the_write_cache_refuses_what_would_overflow_it_and_frees_what_was_written():
    from ball_balance.cli.bag import WriteCache

    frame = 921_600  # one 640x480 bgr8 camera frame
    cache = WriteCache(max_bytes=2 * frame)
    assert cache.offer(("frame", 1), frame) and cache.offer(("frame", 2), frame)
    assert not cache.offer(("frame", 3), frame)  # the writer is behind: dropped, memory bounded
    assert cache.queued_bytes == 2 * frame
    assert cache.get() == ("frame", 1)
    assert cache.queued_bytes == frame and cache.offer(("frame", 4), frame)
    cache.close()
    assert [cache.get(), cache.get(), cache.get()] == [("frame", 2), ("frame", 4), None]
    assert cache.queued_bytes == 0


def test_the_write_cache_takes_a_message_larger_than_itself_when_empty_and_one_at_a_time_at_zero():
    from ball_balance.cli.bag import WriteCache

    small = WriteCache(max_bytes=1000)
    assert small.offer(("map", 1), 5000) and not small.offer(("map", 2), 1)
    none = WriteCache(max_bytes=0)  # rosbag2's --max-cache-size 0: no cache
    assert none.offer(("frame", 1), 921_600) and not none.offer(("frame", 2), 921_600)
    assert none.get() == ("frame", 1) and none.offer(("frame", 3), 921_600)


def test_a_stop_signal_only_raises_the_flag_and_ends_the_nap():
    import os
    import signal
    import time

    from ball_balance.cli.session import StopRequest

    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            stop = StopRequest()
            assert not stop.sleep_until(time.monotonic() + 0.1)   # nothing asked: sleeps it out
            os.kill(os.getpid(), sig)                               # no KeyboardInterrupt
            started = time.monotonic()
            assert stop.sleep_until(started + 30.0) and time.monotonic() - started < 5.0
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)


def test_a_binary_parameter_file_is_named_as_not_a_text_yaml_file(tmp_path, capsys, monkeypatch):
    from ball_balance.cli import main as cli_main
    from ball_balance.cli.session import Session

    binary = tmp_path / "params.yaml"
    binary.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)))
    monkeypatch.setattr(Session, "__init__", lambda *a, **k: pytest.fail("a node was made"))
    assert cli_main.main(["param", "load", "/tracker", str(binary)]) == 1
    assert capsys.readouterr().err == (f"ros2py: cannot read parameter file '{binary}': not a UTF-8 text file "
                                       "(byte 0x89 at offset 0)\n")
    monkeypatch.setattr("os.execv", lambda *a: pytest.fail("started the node"))
    assert cli_main.main(["run", "ball_balance", "ball_tracker", "--ros-args", "--params-file", str(binary)]) == 1
    assert capsys.readouterr().err == (f"ros2py: cannot read parameter file '{binary}': not a UTF-8 text file "
                                       "(byte 0x89 at offset 0)\n")


@pytest.mark.parametrize("reason, shown", [
    ("update_rate must be between 1 and 10000 Hz", "update_rate must be between 1 and 10000 Hz"),
    ("", "refused by the node"),
])
def test_param_set_and_load_print_the_nodes_reason_when_it_refuses(tmp_path, capsys, monkeypatch, reason, shown):
    import contextlib

    from rcl_interfaces.msg import SetParametersResult

    from ball_balance.cli import main as cli_main
    from ball_balance.cli import param

    monkeypatch.setattr(param, "_open", lambda args: contextlib.nullcontext())
    monkeypatch.setattr(param, "set_values", lambda session, node, values: [
        SetParametersResult(successful=False, reason=reason) for _ in values])
    assert cli_main.main(["param", "set", "/controller_manager", "update_rate", "0"]) == 1
    assert capsys.readouterr() == ("", f"ros2py: Setting parameter failed: {shown}\n")
    params = tmp_path / "cm.yaml"
    params.write_text("controller_manager:\n  ros__parameters:\n    update_rate: 0\n")
    assert cli_main.main(["param", "load", "/controller_manager", str(params)]) == 1
    assert capsys.readouterr().out == f"Set parameter update_rate failed: {shown}\n"
