"""`ros2py bag record` and `bag play` on the simulated graph: what a ROS user needs from a bag.

One recording of the simulated arm's camera (60 Hz, sensor-data QoS) and the tracker serves
every check: frames kept, QoS and type hash of every topic, readable by rosbags and by the
MCAP ROS 2 decoder, and replayed into a fresh tracker that answers as the live one did.
"""
import json
import os
import shlex
import signal
import struct
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Optional

import pytest
import yaml

from harness import ROOT, executable, ros_env

pytestmark = [pytest.mark.integration, pytest.mark.slow]

RECORD_S = 20.0
REPLAY_S = 10.0   # bag seconds: on a slow machine the camera keeps 15-20 of its 60 frames a second
# quarter speed: the states compared are the frames both trackers answered, and a fresh tracker
# on a slow, loaded machine answered too few of them at half speed (0 of 64 matched with CI beside)
REPLAY_RATE = 0.25
REPLAYED = ("/camera/image_raw", "/camera/camera_info", "/clock")
DDS_PROFILE = ROOT / "config" / "dds" / "fastdds.xml"  # whole camera frames at full rate


# A plain best-effort subscriber beside the recorder: which camera frames reach any reader.
REFERENCE_READER = textwrap.dedent("""
    import json, sys, time
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CameraInfo, Image
    rclpy.init()
    node = rclpy.create_node('reference_reader')
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)
    got = {'frames': [], 'infos': []}
    stamp = lambda m: m.header.stamp.sec * 1000000000 + m.header.stamp.nanosec
    node.create_subscription(Image, '/camera/image_raw', lambda m: got['frames'].append(stamp(m)), qos)
    node.create_subscription(CameraInfo, '/camera/camera_info', lambda m: got['infos'].append(stamp(m)), qos)
    end = time.monotonic() + float(sys.argv[1])
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.1)
    print(json.dumps(got))
""")


def env(ros_domain):
    extra = {}
    if DDS_PROFILE.exists():
        extra = {"FASTRTPS_DEFAULT_PROFILES_FILE": str(DDS_PROFILE), "FASTDDS_DEFAULT_PROFILES_FILE": str(DDS_PROFILE)}
    return ros_env(ros_domain, **extra)


def header_stamp_ns(cdr: bytes) -> int:
    """std_msgs/Header.stamp of a message that starts with a header (after the 4-byte CDR preamble)."""
    sec, nanosec = struct.unpack_from("<iI", cdr, 4)
    return sec * 1_000_000_000 + nanosec


def read_topics(bag: Path, topics, take_delays_ms: Optional[dict] = None):
    """{topic: [message bytes]}; with take_delays_ms, also {topic: [how late the recorder took
    each message after its publication, ms]} (log time - publish time)."""
    from mcap.reader import make_reader

    found = {t: [] for t in topics}
    with open(bag / f"{bag.name}_0.mcap", "rb") as stream:
        for _, channel, message in make_reader(stream).iter_messages(topics=list(topics)):
            found[channel.topic].append(message.data)
            if take_delays_ms is not None:
                take_delays_ms.setdefault(channel.topic, []).append((message.log_time - message.publish_time) / 1e6)
    return found


def first_log_times_ns(bag: Path, topics) -> dict:
    """{topic: log time of its first message} (a read from the start that stops once all are seen)."""
    from mcap.reader import make_reader

    first = {}
    with open(bag / f"{bag.name}_0.mcap", "rb") as stream:
        for _, channel, message in make_reader(stream).iter_messages(topics=list(topics)):
            first.setdefault(channel.topic, message.log_time)
            if len(first) == len(topics):
                break
    return first


def record_the_simulated_graph(launcher, graph, ros_domain, tmp_path):
    """A RECORD_S recording (-a) of the simulated arm with its camera and the tracker."""
    from ball_tracker_msgs.msg import BallState
    from rclpy.qos import qos_profile_sensor_data

    environment = env(ros_domain)
    # realtime pacing: the recording is about frames, not balancing, and a lock-stepped world on a
    # slow machine publishes camera_info too slowly for the frame count below
    sim = launcher.start([str(ROOT / "scripts" / "sim_arm.sh"), "--param", "camera_rate_hz=60",
                          "--param", "image_reliable=false", "--param", "pacing=realtime"],
                         name="sim_arm", env=environment)
    tracker = launcher.start([executable("ball_tracker"), "--ros-args", "--params-file",
                              str(ROOT / "config" / "ball_tracker.yaml"), "-p", "use_sim_time:=true"],
                             name="ball_tracker", env=environment)
    graph.collect(BallState, "/ball_state", timeout=90, qos=qos_profile_sensor_data,
                  predicate=lambda m: m.tracking_valid)
    bag = tmp_path / "sim_bag"
    # a cache of 1 GB (the default is rosbag2's 100 MiB): this checks which frames reach the
    # recorder; with the whole simulated graph beside one busy process on 2 cores, its writer
    # fell behind by more than 100 MiB once (265 messages lost)
    recorder = launcher.start([executable("ros2py"), "bag", "record", "-a", "-o", str(bag),
                               "--max-cache-size", str(10 ** 9)], name="record", env=environment)
    # As a user does: start it, see it subscribe to the camera, let it record, Ctrl-C. Its start
    # (rclpy's import, discovery, 25 subscriptions) took 10-20 s beside a busy process.
    graph.spin_until(lambda: all(f"Subscribed to topic '/camera/{t}'" in recorder.output()
                                 for t in ("image_raw", "camera_info")) or not recorder.running,
                     120, "the recorder to subscribe to the camera")
    assert recorder.running, recorder.output()
    reference = launcher.start([sys.executable, "-c", REFERENCE_READER, str(RECORD_S)], name="reference",
                               env=environment)
    assert reference.wait(timeout=RECORD_S + 60) == 0, reference.output()
    received = json.loads(reference.output().strip().splitlines()[-1])
    stop(recorder)  # SIGINT: the recorder writes what it has taken and finishes the file
    assert recorder.wait(timeout=5) == 0, recorder.output()
    print(recorder.output())   # the recorder's subscriptions and progress lines, shown if a check fails
    return bag, environment, (sim, tracker), received


def stop(process) -> None:
    os.killpg(process.popen.pid, signal.SIGINT)
    try:
        process.wait(timeout=20)
    except subprocess.TimeoutExpired:
        os.killpg(process.popen.pid, signal.SIGKILL)
        process.wait(timeout=5)


@pytest.mark.timeout(600)  # a simulated graph, a 20 s recording and a replay at quarter speed
def test_a_recording_of_the_simulated_graph_keeps_its_frames_reads_everywhere_and_replays(
        launcher, graph, ros_domain, tmp_path):
    bag, environment, live, received = record_the_simulated_graph(launcher, graph, ros_domain, tmp_path)
    check_frames_qos_and_type_hashes(bag, received)
    check_readable_by_rosbags_and_the_mcap_ros2_decoder(bag)
    for process in live:  # the live graph is gone: only the bag speaks now
        stop(process)
    check_replay_drives_a_fresh_tracker_to_the_recorded_ball_state(bag, environment, launcher, graph)


def check_frames_qos_and_type_hashes(bag: Path, received: dict) -> None:
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == "mcap" and info["ros_distro"] == "jazzy"
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    assert {"/camera/image_raw", "/camera/camera_info", "/ball_state", "/joint_states", "/clock"} <= set(topics)
    for name, entry in topics.items():
        meta = entry["topic_metadata"]
        assert meta["type_description_hash"].startswith("RIHS01_"), name
        assert meta["offered_qos_profiles"], name
        assert all(p["reliability"] in ("reliable", "best_effort") for p in meta["offered_qos_profiles"]), name
    assert topics["/camera/image_raw"]["topic_metadata"]["offered_qos_profiles"][0]["reliability"] == "best_effort"

    # Every camera frame comes with a camera_info of the same stamp: the frames published
    # while both were recorded are the camera_info stamps between the first and the last frame.
    delays_ms = {}
    data = read_topics(bag, ["/camera/image_raw", "/camera/camera_info"], delays_ms)
    recorded = kept_frames({header_stamp_ns(d) for d in data["/camera/image_raw"]},
                           [header_stamp_ns(d) for d in data["/camera/camera_info"]])
    reference = kept_frames(set(received["frames"]), received["infos"])
    frame_delays_ms = sorted(delays_ms["/camera/image_raw"])
    # frames taken later than the recorder's queue depth of publish periods were lost
    print(f"camera frames kept: bag {recorded[0]} of {recorded[1]}, "
          f"a plain subscriber beside it {reference[0]} of {reference[1]}; the recorder took frames "
          f"{frame_delays_ms[len(frame_delays_ms) // 2]:.0f} ms after publication (median), "
          f"{frame_delays_ms[int(0.99 * len(frame_delays_ms))]:.0f} ms (p99)")
    assert recorded[1] >= 60, recorded  # the sim runs below real time on a loaded machine
    # On an overloaded machine every best-effort reader loses frames alike (a plain rclpy
    # subscriber lost 11 of 385 where the recorder lost 13 at load 10-15; on a slower machine with
    # one busy process 27 of 309 where the recorder lost 26 of 226): the recorder must keep 99 % of
    # what the camera published, or be within 5 points of that plain subscriber (which frames a
    # starved best-effort reader loses is chance; a recorder that falls behind loses far more).
    fraction = recorded[0] / recorded[1]
    assert fraction >= 0.99 or fraction >= reference[0] / reference[1] - 0.05, (recorded, reference)


def kept_frames(frames: set, infos: list) -> tuple:
    """(frames kept, frames published) between the first and the last frame received."""
    published = [s for s in infos if min(frames) <= s <= max(frames)]
    return sum(1 for s in published if s in frames), len(published)


def check_readable_by_rosbags_and_the_mcap_ros2_decoder(bag: Path) -> None:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag) as reader:
        connections = {c.topic: c for c in reader.connections}
        assert connections["/camera/image_raw"].msgtype == "sensor_msgs/msg/Image"
        assert connections["/camera/image_raw"].ext.offered_qos_profiles
        image = next(store.deserialize_cdr(raw, c.msgtype) for c, _, raw in
                     reader.messages(connections=[connections["/camera/image_raw"]]))
        assert (image.width, image.height, image.encoding) == (640, 480, "bgr8")
        assert len(image.data) == 640 * 480 * 3
    seen = {}
    with open(bag / f"{bag.name}_0.mcap", "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, _, decoded in reader.iter_decoded_messages(topics=["/ball_state", "/joint_states"]):
            seen.setdefault(channel.topic, decoded)
            if len(seen) == 2:
                break
    assert seen["/ball_state"].header.frame_id == "plate_center"
    assert len(seen["/joint_states"].name) == 6


def check_replay_drives_a_fresh_tracker_to_the_recorded_ball_state(bag: Path, environment, launcher, graph) -> None:
    from ball_tracker_msgs.msg import BallState
    from rclpy.qos import qos_profile_sensor_data
    from rclpy.serialization import deserialize_message

    recorded = {header_stamp_ns(d): deserialize_message(d, BallState)
                for d in read_topics(bag, ["/ball_state"])["/ball_state"]}
    # play from where the bag holds every topic replayed and /ball_state: the recorder subscribes
    # to the topics in the order it discovers them, and on a loaded machine /ball_state came
    # 10-20 s after the camera, and /clock seconds after /ball_state (CI: 0 of 27 matched)
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    all_there_ns = max(first_log_times_ns(bag, ("/ball_state",) + REPLAYED).values())
    offset_s = (all_there_ns - info["starting_time"]["nanoseconds_since_epoch"]) / 1e9
    tracker = launcher.start([executable("ball_tracker"), "--ros-args", "--params-file",
                              str(ROOT / "config" / "ball_tracker.yaml"), "-p", "use_sim_time:=true"],
                             name="replay_tracker", env=environment)
    # the tracker subscribes to the images once it sees their publisher (the player's, within
    # its --delay): wait for its node
    graph.spin_until(lambda: "ball_tracker" in graph.node.get_node_names(), 60, "the replay tracker")
    replayed = []
    graph.node.create_subscription(BallState, "/ball_state", replayed.append, qos_profile_sensor_data)
    player = launcher.start([executable("ros2py"), "bag", "play", str(bag), "--topics", *REPLAYED, "--delay", "3",
                             "--playback-duration", str(REPLAY_S), "--rate", str(REPLAY_RATE),
                             "--start-offset", f"{max(0.0, offset_s):.3f}"],
                            name="bag_play", env=environment)
    graph.spin_until(lambda: not player.running, REPLAY_S / REPLAY_RATE + 60, "bag play to finish")
    assert player.wait(timeout=5) == 0, player.output()
    graph.spin_until(lambda: len(replayed) >= 10, 20, "replayed ball states")
    assert tracker.running, tracker.output()
    same_frame = [(recorded[header_stamp_ns_of(m)], m) for m in replayed if header_stamp_ns_of(m) in recorded]
    matched = [(a, b) for a, b in same_frame if a.tracking_valid and b.tracking_valid][5:]  # the filter settles
    assert len(matched) >= 20, (f"{len(matched)} replayed ball states matched recorded ones of {len(replayed)} "
                                f"({len(same_frame)} of the same frame, "
                                f"{sum(m.tracking_valid for m in replayed)} replayed ones valid)")
    worst = max(max(abs(a.x - b.x), abs(a.y - b.y)) for a, b in matched)
    print(f"replayed /ball_state: {len(matched)} of {len(replayed)} matched a recorded one, "
          f"worst difference {worst * 1000:.3f} mm")
    assert worst <= 0.001, f"replayed /ball_state differs by up to {worst * 1000:.2f} mm"


def header_stamp_ns_of(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


TALKER = textwrap.dedent("""
    import sys
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String
    rclpy.init()
    node = rclpy.create_node('talker_' + sys.argv[1])
    pub = node.create_publisher(String, '/mixed', QoSProfile(depth=10, reliability=ReliabilityPolicy[sys.argv[1]]))
    node.create_timer(0.05, lambda: pub.publish(String(data=sys.argv[1])))
    rclpy.spin(node)
""")


def test_record_rematches_when_a_best_effort_publisher_joins_a_reliable_topic(launcher, graph, tmp_path):
    from std_msgs.msg import String

    launcher.start([sys.executable, "-c", TALKER, "RELIABLE"], name="reliable_talker")
    graph.wait_for_topic("/mixed", timeout=30)
    bag = tmp_path / "mixed"
    recorder = launcher.start([executable("ros2py"), "bag", "record", "-o", str(bag), "/mixed", "/not_published"],
                              name="record")
    # the second publisher joins only once the recorder has matched the first (on a loaded
    # machine its discovery of the first can otherwise take long enough to see both at once)
    graph.spin_until(lambda: "Subscribed to topic '/mixed' (reliable/volatile)" in recorder.output(), 30,
                     "the recorder to subscribe")
    graph.collect(String, "/mixed", timeout=30)
    launcher.start([sys.executable, "-c", TALKER, "BEST_EFFORT"], name="best_effort_talker")
    graph.spin_until(lambda: "re-matched the QoS of /mixed: reliable/volatile -> best_effort/volatile"
                     in recorder.output(), 30, "the recorder to re-match")
    graph.collect(String, "/mixed", timeout=30, qos=_best_effort(), predicate=lambda m: m.data == "BEST_EFFORT")

    def progress_lines_since_rematch() -> int:
        return recorder.output().split("re-matched the QoS", 1)[-1].count(" msgs in ")

    graph.spin_until(lambda: progress_lines_since_rematch() >= 2, 40, "the recorder's progress (every 5 s)")
    stop(recorder)  # SIGINT: the recorder finishes the file
    assert recorder.wait(timeout=5) == 0, recorder.output()
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    (topic,) = info["topics_with_message_count"]  # /not_published has no publisher: skipped
    meta = topic["topic_metadata"]
    assert meta["name"] == "/mixed" and meta["type_description_hash"].startswith("RIHS01_")
    assert sorted(p["reliability"] for p in meta["offered_qos_profiles"]) == ["best_effort", "reliable"]
    texts = {d[-12:] for d in read_topics(bag, ["/mixed"])["/mixed"]}
    assert any(b"BEST_EFFORT" in t for t in texts) and any(b"RELIABLE" in t for t in texts)


def test_record_finishes_its_bag_on_sigint_when_started_with_sigint_ignored(launcher, graph, tmp_path):
    """A background job of a script (`ros2py bag record ... &`) starts with SIGINT ignored;
    `kill -INT` must still end the recording with a complete bag, as rosbag2's does."""
    bag = tmp_path / "background"
    recorder = launcher.start(["bash", "-c", f"trap '' INT; exec {shlex.quote(executable('ros2py'))} bag record "
                               f"-o {shlex.quote(str(bag))} /nothing_published"], name="record")
    graph.spin_until(lambda: "Recording to" in recorder.output(), 60, "the recorder to start")
    stop(recorder)
    assert recorder.wait(timeout=5) == 0, recorder.output()
    assert "Recorded 0 messages" in recorder.output()
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["topics_with_message_count"] == []


COUNTER = textwrap.dedent("""
    import rclpy
    from std_msgs.msg import String
    rclpy.init()
    node = rclpy.create_node('counter')
    pub = node.create_publisher(String, '/count', 10)
    sent = [0]
    def tick():
        pub.publish(String(data=str(sent[0])))
        sent[0] += 1
    node.create_timer(0.05, tick)
    rclpy.spin(node)
""")


def test_play_loops_at_a_rate_with_the_bags_time_on_clock(launcher, graph, tmp_path):
    """`bag play --rate 4 --loop --clock 20 --topics /count`: the recording again and again,
    /clock carrying the bag's time, running 4 times as fast as the wall clock."""
    from rclpy.qos import QoSProfile
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import String

    counter = launcher.start([sys.executable, "-c", COUNTER], name="counter")
    graph.wait_for_topic("/count", timeout=30)
    bag = tmp_path / "count"
    # --duration counts from the recorder's start, and on a loaded machine matching /count took
    # 2.5 s of a 3 s recording (9 messages): 8 s leaves at least 10 even then
    result = launcher.run([executable("ros2py"), "bag", "record", "-o", str(bag), "/count", "--duration", "8"],
                          timeout=90)
    assert result.returncode == 0, result.stderr
    stop(counter)
    recorded = [d for d in read_topics(bag, ["/count"])["/count"]]
    assert len(recorded) >= 10, len(recorded)
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    bag_start_ns = info["starting_time"]["nanoseconds_since_epoch"]
    bag_end_ns = bag_start_ns + info["duration"]["nanoseconds"]

    received, clocks = [], []  # (wall s, value)
    count_subscription = graph.node.create_subscription(String, "/count", lambda m: received.append(m.data), 100)
    graph.node.create_subscription(
        Clock, "/clock", lambda m: clocks.append((time.monotonic(), m.clock.sec * 1_000_000_000 + m.clock.nanosec)),
        QoSProfile(depth=100))
    player = launcher.start([executable("ros2py"), "bag", "play", str(bag), "--rate", "4", "--loop", "--clock", "20",
                             "--topics", "/count", "--delay", "2"], name="bag_play")
    graph.spin_until(lambda: len(received) >= 4 * len(recorded), 120, "four passes of the bag")
    stop(player)  # Ctrl-C: it says what it played, no traceback
    assert player.wait(timeout=5) == 0, player.output()
    assert "Played" in player.output() and "Traceback" not in player.output(), player.output()
    first = received.index(received[0], 1)  # the first message again: the second pass begins
    assert received[:first] == received[first:2 * first]  # every pass plays the same messages in order
    outside = [(v - bag_start_ns) / 1e6 for _, v in clocks if not bag_start_ns <= v <= bag_end_ns]
    assert not outside, (outside, info["duration"]["nanoseconds"] / 1e6)  # the bag's time
    # bag time runs at 4x the wall clock: its forward steps over all passes against the wall
    # time they took (loose: receive times jitter on a busy machine, each pass reopens the file)
    advanced_s = sum(max(0, b[1] - a[1]) for a, b in zip(clocks, clocks[1:])) / 1e9
    ratio = advanced_s / (clocks[-1][0] - clocks[0][0])
    assert 2.5 < ratio < 5.0, ratio

    # --start-offset 1.5: exactly the messages recorded from 1.5 s into the bag on, in order
    from mcap.reader import make_reader
    from rclpy.serialization import deserialize_message

    with open(bag / "count_0.mcap", "rb") as stream:
        later = [deserialize_message(m.data, String).data for _, _, m in make_reader(stream).iter_messages()
                 if m.log_time >= bag_start_ns + 1_500_000_000]
    # a new subscription: the first one may still hold messages of the looping player
    graph.node.destroy_subscription(count_subscription)
    received = []
    graph.node.create_subscription(String, "/count", lambda m: received.append(m.data), 100)
    player = launcher.start([executable("ros2py"), "bag", "play", str(bag), "--rate", "4", "--topics", "/count",
                             "--delay", "5", "--start-offset", "1.5"], name="bag_play_offset")
    graph.spin_until(lambda: not player.running, 60, "bag play --start-offset to finish")
    assert player.wait(timeout=5) == 0, player.output()
    graph.spin_for(1.0)  # the last messages in flight
    # none from before the offset, in the bag's order (on a loaded machine the first few can go
    # out before this process has matched the player's new publisher: with --delay 2, 19 of 29
    # were lost in 2 of 5 runs; the player waits 5 s)
    assert later and received and all(m in later for m in received), (received, later)
    assert received == sorted(received, key=later.index) and len(received) >= len(later) // 2, (received, later)


def _best_effort():
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    return QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
