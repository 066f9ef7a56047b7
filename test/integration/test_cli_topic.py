"""`ros2py` against real processes: topics, nodes, parameters, bags, run; one-line errors."""
import os
import re
import signal
import struct
import textwrap
import time
from pathlib import Path

import pytest

from harness import executable, python_cmd

pytestmark = pytest.mark.integration

BALL_STATE_PUBLISHER = textwrap.dedent("""
    import rclpy
    from ball_tracker_msgs.msg import BallState
    from rclpy.qos import qos_profile_sensor_data
    rclpy.init()
    node = rclpy.create_node('ball_state_source')
    node.declare_parameter('gain', 0.5)
    node.declare_parameter('limits.max_tilt', 3)
    node.declare_parameter('frames', ['world', 'plate'])
    pub = node.create_publisher(BallState, '/ball_state', qos_profile_sensor_data)
    msg = BallState(x=0.125, y=-0.0625, vx=0.5, vy=-0.25, ball_found=True, tracking_valid=True,
                    markers_found=3, pixel_u=320.5, pixel_v=240.25)
    msg.header.frame_id = 'plate_center'
    node.create_timer(0.05, lambda: pub.publish(msg))
    rclpy.spin(node)
""")


IMAGE_PUBLISHER = textwrap.dedent("""
    import rclpy
    from sensor_msgs.msg import Image
    rclpy.init()
    node = rclpy.create_node('image_source')
    pub = node.create_publisher(Image, '/image', 10)
    msg = Image(height=480, width=640, encoding='rgb8', step=1920)
    msg.data = bytes(640 * 480 * 3)
    node.create_timer(0.1, lambda: pub.publish(msg))
    rclpy.spin(node)
""")
WIDGET_PUBLISHER = Path(__file__).parent / "peers" / "cyclone_widget_publisher.py"
# a process's file size limit (RLIMIT_FSIZE), then the command: a disk that fills up, for one
# process; Python ignores SIGXFSZ, so a write beyond the limit fails with EFBIG. (Fast DDS's
# shared-memory segments are files too: under the limit it logs that and talks over UDP.)
WITH_FILE_SIZE_LIMIT = "import os, resource, sys; limit = int(sys.argv[1]); " \
    "resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit)); os.execv(sys.argv[2], sys.argv[2:])"


def ros2py(launcher, *args, timeout=40, input=None):
    return launcher.run([executable("ros2py"), *args], timeout=timeout, input=input)


def one_line_error(result, *fragments):
    assert result.returncode != 0
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("ros2py: ")
    for fragment in fragments:
        assert fragment in lines[0]


@pytest.fixture
def ball_state_source(launcher, graph):
    launcher.start(python_cmd("-c", BALL_STATE_PUBLISHER), name="ball_state_source")
    graph.wait_for_topic("/ball_state", timeout=30)


def test_topic_echo_shows_a_ball_state_published_by_another_process(launcher, ball_state_source):
    result = ros2py(launcher, "topic", "echo", "/ball_state", "--once")
    assert result.returncode == 0, result.stderr
    assert result.stdout == (
        "header:\n  stamp:\n    sec: 0\n    nanosec: 0\n  frame_id: plate_center\n"
        "x: 0.125\ny: -0.0625\nvx: 0.5\nvy: -0.25\nball_found: true\ntracking_valid: true\n"
        "markers_found: 3\npixel_u: 320.5\npixel_v: 240.25\n---\n")
    field = ros2py(launcher, "topic", "echo", "/ball_state", "--once", "--field", "header.frame_id")
    assert field.stdout == "plate_center\n---\n"


def test_topic_list_info_hz_and_node_list_see_the_publisher(launcher, ball_state_source):
    listing = ros2py(launcher, "topic", "list", "-t")
    assert "/ball_state [ball_tracker_msgs/msg/BallState]" in listing.stdout.splitlines()
    info = ros2py(launcher, "topic", "info", "/ball_state", "-v").stdout
    assert info.startswith("Type: ball_tracker_msgs/msg/BallState\n\nPublisher count: 1\n\n")
    assert "Node name: ball_state_source\n" in info and "  Reliability: BEST_EFFORT\n" in info
    # 6 s: on a busy machine the subscription can take 3 s to match (no line at all in 3.5 s,
    # 1 run of 7 at load 9-14)
    hz = ros2py(launcher, "topic", "hz", "/ball_state", "--duration", "6").stdout
    rates = [float(line.split(":")[1]) for line in hz.splitlines() if line.startswith("average rate:")]
    # published at 20 Hz; judged over the longest window (the last line): the first windows
    # hold a handful of arrivals, and a publisher starved on a busy machine sends in bursts
    # (4 Hz and 40 Hz over its first 5 and 19 messages at load 15)
    assert rates and 10.0 < rates[-1] < 30.0, hz
    assert "\tmin: " in hz and " std dev: " in hz and " window: " in hz
    bw = ros2py(launcher, "topic", "bw", "/ball_state", "--duration", "8").stdout
    assert bw.startswith("Subscribed to [/ball_state]\n"), bw
    # a BallState is under 100 bytes: at 20 Hz, B/s or KB/s
    assert " messages\n\tMessage size mean: " in bw and ("B/s from " in bw), bw
    listed_in(launcher, ("node", "list"), "/ball_state_source")
    listed_in(launcher, ("service", "list", "-t"),
              "/ball_state_source/get_parameters [rcl_interfaces/srv/GetParameters]")
    # the same listing both ways: a second call is a new participant that may see less of the graph
    info = listed_in(launcher, ("node", "info", "/ball_state_source"),
                     "    /ball_state_source/describe_parameters: rcl_interfaces/srv/DescribeParameters")
    assert "    /ball_state: ball_tracker_msgs/msg/BallState\n" in info, info
    assert info.startswith("/ball_state_source\n  Subscribers:\n\n  Publishers:\n"), info
    assert "  Service Servers:\n    /ball_state_source/describe_parameters: rcl_interfaces/srv/DescribeParameters\n" \
        in info
    assert info.endswith("  Action Servers:\n\n  Action Clients:\n\n"), info


def listed_in(launcher, verb, line: str, deadline_s: float = 60.0) -> str:
    """`ros2py VERB` prints line, within a few calls. Each call is a new participant, and a
    listing ends once the graph has been still for 2 s; on a busy machine the publisher's
    participant answered a new one later than that (node list showed only the test's own node
    in 1 of about 10 runs with one busy process). Returns the listing that printed it."""
    deadline = time.monotonic() + deadline_s
    while True:
        result = ros2py(launcher, *verb)
        if line in result.stdout.splitlines() or time.monotonic() > deadline:
            break
    assert line in result.stdout.splitlines(), result.stdout + result.stderr
    return result.stdout


def test_topic_pub_reaches_a_subscriber_in_another_process(launcher, graph):
    from std_msgs.msg import String

    launcher.start([executable("ros2py"), "topic", "pub", "-r", "10", "/chatter", "std_msgs/msg/String",
                    "{data: hello from ros2py}"], name="pub")
    (msg,) = graph.collect(String, "/chatter", timeout=30)
    assert msg.data == "hello from ros2py"


def test_topic_pub_with_a_type_other_than_the_graph_shows_is_refused(launcher, ball_state_source):
    one_line_error(ros2py(launcher, "topic", "pub", "/ball_state", "std_msgs/msg/String", "{data: x}", "--once",
                          "--max-wait-time-secs", "20"),
                   "'/ball_state' has type ball_tracker_msgs/msg/BallState on the graph, not std_msgs/msg/String")


def test_param_get_set_dump_through_the_node_services(launcher, ball_state_source):
    assert ros2py(launcher, "param", "get", "ball_state_source", "gain").stdout == "Double value is: 0.5\n"
    assert ros2py(launcher, "param", "set", "/ball_state_source", "gain", "0.75").stdout == \
        "Set parameter successful\n"
    assert ros2py(launcher, "param", "get", "ball_state_source", "gain", "--hide-type").stdout == "0.75\n"
    dump = ros2py(launcher, "param", "dump", "ball_state_source").stdout
    assert dump.startswith("/ball_state_source:\n  ros__parameters:\n")
    assert "    gain: 0.75\n" in dump and "    limits:\n      max_tilt: 3\n" in dump
    assert "    frames:\n    - world\n    - plate\n" in dump
    refused = ros2py(launcher, "param", "set", "ball_state_source", "gain", "fast")
    one_line_error(refused, "Setting parameter failed")


def test_bad_input_gives_one_line_and_nonzero_exit(launcher, ros_domain, tmp_path):
    one_line_error(ros2py(launcher, "topic", "echo", "/no_such_topic", "--spin-time", "1"),
                   "topic '/no_such_topic' not found")
    one_line_error(ros2py(launcher, "topic", "pub", "/x", "std_msgs/msg/Strng", "{data: hi}", "--once"),
                   "std_msgs/msg/Strng")
    one_line_error(ros2py(launcher, "topic", "pub", "/x", "std_msgs/msg/String", "{data: [hi", "--once"),
                   "not valid YAML")
    one_line_error(ros2py(launcher, "topic", "pub", "/x", "std_msgs/msg/Int32", "{data: hi}", "--once"),
                   "field 'data' (int32)")
    bad_file = tmp_path / "bad.yaml"
    bad_file.write_text("ball_state_source:\n  ros__parameters:\n    gain: [0.5\n")
    one_line_error(ros2py(launcher, "param", "load", "ball_state_source", str(bad_file)),
                   "not valid YAML", str(bad_file))
    one_line_error(ros2py(launcher, "run", "ball_balance", "no_such_node"), "No executable 'no_such_node'")
    # a malformed parameter file given to a node started the ros2 way
    one_line_error(ros2py(launcher, "run", "ball_balance", "ball_tracker", "--ros-args", "--params-file",
                          str(bad_file)), "not valid YAML", str(bad_file))


def test_bad_names_and_numbers_are_one_line_and_exit_2(launcher):
    for args, fragment in [
        (("topic", "pub", "bad name", "std_msgs/msg/String", "{data: hi}", "--once"),
         "'bad name' is not a valid topic name: it must not"),
        (("topic", "echo", "bad name", "std_msgs/msg/String"), "'bad name' is not a valid topic name: it must not"),
        (("service", "call", "bad name", "std_srvs/srv/Trigger"), "'bad name' is not a valid service name: it must"),
        (("action", "send_goal", "bad name", "control_msgs/action/FollowJointTrajectory", "{}"),
         "'bad name' is not a valid action name: it must not contain"),
        (("service", "call", "/x", "std_srvs/srv/Trigger", "--timeout", "-5"),
         "argument --timeout: expected a number > 0, got '-5'"),
        (("tf", "echo", "a", "b", "--count", "-1"), "argument --count: expected an integer > 0, got '-1'"),
        (("bag", "record", "/x", "--duration", "-1"), "argument --duration: expected a number > 0, got '-1'"),
    ]:
        result = ros2py(launcher, *args)
        one_line_error(result, fragment)
        assert result.returncode == 2 and "c:" not in result.stderr, result.stderr  # no rcl C source location


def write_chatter_bag(folder: Path, count: int = 79) -> Path:
    """A bag as `bag record` writes it, without a recording: /chatter, `count` messages 10 ms apart, in
    chunks of 4 KiB."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from ball_balance.cli.bag_format import message_definition
    from ball_balance.cli.mcap_write import McapWriter

    folder.mkdir()
    path = folder / f"{folder.name}_0.mcap"
    with open(path, "wb") as stream:
        writer = McapWriter(stream, chunk_size_bytes=4096)
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema("std_msgs/msg/String", "ros2msg",
                                        message_definition("std_msgs/msg/String").encode())
        channel = writer.register_channel("/chatter", "cdr", schema, {"offered_qos_profiles": ""})
        for i in range(count):
            stamp_ns = 1_700_000_000_000_000_000 + i * 10_000_000
            writer.add_message(channel, log_time=stamp_ns, publish_time=stamp_ns,
                               data=serialize_message(String(data=f"message {i} " * 4)), sequence=i)
        writer.finish()
    return path


def test_bag_play_of_a_damaged_bag_says_where_and_how_much_it_played(launcher, tmp_path):
    """One changed byte in the length of a message in the bag's second chunk: play publishes the
    first chunk, then one line names the file and the byte, and the exit code is 1."""
    intact = write_chatter_bag(tmp_path / "run1")
    data = bytearray(intact.read_bytes())
    chunks, offset = [], 8  # after the magic bytes: records of opcode, length, body
    while len(chunks) < 2:
        opcode, length = struct.unpack_from("<BQ", data, offset)
        chunks += [offset] if opcode == 0x06 else []
        offset += 9 + length
    first_message = chunks[1] + 9 + 40  # the second chunk's record head, fields and empty compression name
    data[first_message + 3] ^= 0x10
    damaged = tmp_path / "damaged" / "damaged_0.mcap"
    damaged.parent.mkdir()
    damaged.write_bytes(data)
    result = ros2py(launcher, "bag", "play", str(damaged.parent), "--rate", "20", timeout=90)
    assert result.returncode == 1 and result.stdout == "", result.stderr
    playing, error = result.stderr.strip().splitlines()
    assert playing.startswith("Playing /chatter from "), result.stderr
    match = re.fullmatch(rf"ros2py: {re.escape(str(damaged))}: damaged at byte {first_message} \(a record's length "
                         r"runs past the end of its chunk\); played (\d+) of 79 messages", error)
    assert match and 0 < int(match.group(1)) < 79, error
    one_line_error(ros2py(launcher, "bag", "info", str(damaged.parent)), f"{damaged}: damaged at byte {first_message}")
    one_line_error(ros2py(launcher, "bag", "play", str(intact.parent), "--start-offset", "1000"),
                   "--start-offset 1000 s is past the end of the bag", "is 0.780 s long")


def test_run_execs_an_installed_executable(launcher, ball_state_source):
    result = ros2py(launcher, "run", "ball_balance", "ros2py", "topic", "list")
    assert result.returncode == 0 and "/ball_state" in result.stdout.splitlines()


def recorded_so_far(output: str) -> int:
    """The message count of the recorder's latest progress line ('[  5.0 s] 12 msgs in 1 topics ...')."""
    counts = re.findall(r"\] (\d+) msgs in ", output)
    return int(counts[-1]) if counts else 0


def test_bag_record_writes_mcap_that_decodes_to_the_published_messages(launcher, graph, ball_state_source, tmp_path):
    from ball_tracker_msgs.msg import BallState
    from mcap.reader import make_reader
    from rclpy.serialization import deserialize_message

    out = tmp_path / "ball_bag"
    recorder = launcher.start([executable("ros2py"), "bag", "record", "-o", str(out), "/ball_state"], name="bag")
    # until its progress line counts 5 messages (a fixed 4 s recorded none at load 15:
    # discovery and the subscription's match took longer)
    graph.spin_until(lambda: recorded_so_far(recorder.output()) >= 5 or not recorder.running, 60,
                     "the recorder to count 5 messages")
    assert recorder.running, recorder.output()
    os.killpg(recorder.popen.pid, signal.SIGINT)
    assert recorder.wait(timeout=20) == 0, recorder.output()
    assert "Recorded " in recorder.output()

    with open(out / "ball_bag_0.mcap", "rb") as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == "ros2"
        records = list(reader.iter_messages())
        (rosbag2_record,) = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
    assert "version: 9" in rosbag2_record.metadata["serialized_metadata"]
    assert len(records) >= 5
    schema, channel, message = records[0]
    assert (schema.name, schema.encoding) == ("ball_tracker_msgs/msg/BallState", "ros2msg")
    assert b"float64 pixel_u" in schema.data and b"MSG: std_msgs/Header" in schema.data
    assert (channel.topic, channel.message_encoding) == ("/ball_state", "cdr")
    assert "offered_qos_profiles" in channel.metadata
    msg = deserialize_message(message.data, BallState)
    assert (msg.x, msg.markers_found, msg.header.frame_id) == (0.125, 3, "plate_center")
    metadata = (out / "metadata.yaml").read_text()
    assert "storage_identifier: mcap" in metadata and f"message_count: {len(records)}" in metadata
    info = ros2py(launcher, "bag", "info", str(out)).stdout
    assert f"Messages:          {len(records)}\n" in info and "ROS Distro:        jazzy\n" in info
    assert f"Topic: /ball_state | Type: ball_tracker_msgs/msg/BallState | Count: {len(records)} |" in info


def test_bag_record_stops_with_one_line_when_the_file_cannot_grow_and_keeps_what_it_wrote(launcher, graph, tmp_path):
    from mcap.exceptions import EndOfFile
    from mcap.records import Message
    from mcap.stream_reader import StreamReader

    launcher.start(python_cmd("-c", IMAGE_PUBLISHER), name="image_source")
    graph.wait_for_topic("/image", timeout=30)
    out = tmp_path / "full_bag"
    limit_bytes = 3_000_000  # three 900 KiB frames: the fourth chunk does not fit
    recorder = launcher.start(python_cmd("-c", WITH_FILE_SIZE_LIMIT, str(limit_bytes), executable("ros2py"),
                                         "bag", "record", "-o", str(out), "/image"), name="bag")
    assert recorder.wait(timeout=120) == 1, recorder.output()
    errors = [line for line in recorder.output().splitlines() if line.startswith("ros2py: ")]
    assert len(errors) == 1 and "recording stopped: cannot write" in errors[0] and "File too large" in errors[0], \
        recorder.output()
    written = int(re.search(r"The (\d+) messages written before it", errors[0]).group(1))
    assert written >= 1, errors[0]
    readable = 0  # as a recovering reader scans the file: record by record, up to the cut
    with open(out / "full_bag_0.mcap", "rb") as stream:
        try:
            for record in StreamReader(stream).records:
                readable += isinstance(record, Message)
        except EndOfFile:  # the chunk cut short by the limit ends the file
            pass
    assert readable == written, (readable, errors[0])
    one_line_error(ros2py(launcher, "bag", "info", str(out)), "ends before its footer", "mcap recover")
    (out / "not_a_bag.mcap").write_text("hello")
    one_line_error(ros2py(launcher, "bag", "info", str(out / "not_a_bag.mcap")), "is not an MCAP file")


def test_bag_record_all_skips_a_topic_of_a_type_not_installed_and_records_the_rest(
        launcher, graph, ball_state_source, tmp_path):
    launcher.start(python_cmd(str(WIDGET_PUBLISHER)), name="cyclone_widget")
    graph.wait_for_topic("/widget", timeout=30)
    out = tmp_path / "all_bag"
    recorder = launcher.start([executable("ros2py"), "bag", "record", "-a", "-o", str(out)], name="bag")
    graph.spin_until(lambda: recorded_so_far(recorder.output()) >= 5 or not recorder.running, 60,
                     "the recorder to count 5 messages")
    assert recorder.running, recorder.output()
    os.killpg(recorder.popen.pid, signal.SIGINT)
    assert recorder.wait(timeout=20) == 0, recorder.output()
    output = recorder.output()
    assert "skipping topic '/widget': unknown msg type 'acme_msgs/msg/Widget'" in output, output
    info = ros2py(launcher, "bag", "info", str(out)).stdout
    assert "Topic: /ball_state | Type: ball_tracker_msgs/msg/BallState" in info and "/widget" not in info, info
