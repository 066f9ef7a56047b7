"""`ros2py bag record -o OUT TOPICS...`: MCAP in rosbag2's layout, readable by Foxglove,
PlotJuggler and `ros2 bag`.

What rosbag2's MCAP storage writes, and so do we:
- profile `ros2`; one schema per type, named `pkg/msg/Type`, encoding `ros2msg`, holding the
  .msg text followed by every nested type's text after a line of 80 '=' and `MSG: pkg/Type`;
- one channel per topic, message encoding `cdr`, metadata `offered_qos_profiles` (YAML) and
  `topic_type_hash`;
- messages as the publisher's CDR bytes (a raw subscription: no decode, no re-encode), with
  log and publish time in nanoseconds since the epoch;
- a metadata record `rosbag2` (`serialized_metadata`, `ROS_DISTRO`), and the bag folder
  OUT/ holding OUT_0.mcap and a rosbag2 `metadata.yaml` (format version 8).
"""
from __future__ import annotations

import os
import re
import signal
import struct
import sys
import time
from typing import Dict, List, Optional

from ball_balance.cli.errors import CliError
from ball_balance.cli.messages import split_type_name
from ball_balance.cli.run import prefixes
from ball_balance.cli.session import Session, absolute_name, is_hidden

PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
              "int32", "uint32", "int64", "uint64", "string", "wstring"}
SEPARATOR = "=" * 80


# --- message definitions (schema text) --------------------------------------------------
def msg_file_text(package: str, name: str) -> str:
    for prefix in prefixes():
        path = os.path.join(prefix, "share", package, "msg", f"{name}.msg")
        if os.path.isfile(path):
            with open(path, encoding="utf-8") as handle:
                return handle.read()
    raise CliError(f"cannot find the definition of {package}/msg/{name} (no {name}.msg in AMENT_PREFIX_PATH)")


def nested_type_of(line: str, package: str) -> Optional[str]:
    """'pkg/Type' for a .msg line declaring a field of a non-primitive type, else None."""
    code = line.split("#", 1)[0].strip()
    if not code or code == "---" or re.match(r"\S+\s+\w+\s*=", code):  # blank, separator, constant
        return None
    base = code.split()[0].split("[", 1)[0].split("<=", 1)[0]
    if base in PRIMITIVES:
        return None
    if "/" in base:
        parts = base.split("/")
        return f"{parts[0]}/{parts[-1]}"
    return "std_msgs/Header" if base == "Header" else f"{package}/{base}"


def nested_types(text: str, package: str) -> List[str]:
    """'pkg/Type' of every non-primitive field in a .msg text, in order of appearance."""
    found = []
    for line in text.splitlines():
        full = nested_type_of(line, package)
        if full and full not in found:
            found.append(full)
    return found


def message_definition(type_name: str) -> str:
    """The full ros2msg schema text of a message type, dependencies appended."""
    package, _, name = split_type_name(type_name)
    root = msg_file_text(package, name)
    text, queue, seen = root, nested_types(root, package), set()
    while queue:
        dependency = queue.pop(0)
        if dependency in seen:
            continue
        seen.add(dependency)
        dep_package, dep_name = dependency.split("/")
        dep_text = msg_file_text(dep_package, dep_name)
        text += f"\n{SEPARATOR}\nMSG: {dependency}\n{dep_text}"
        queue.extend(d for d in nested_types(dep_text, dep_package) if d not in seen)
    return text


# --- QoS as rosbag2 records it ----------------------------------------------------------
_INFINITE = (9223372036, 854775807)


def _duration(d) -> Dict[str, int]:
    ns = d.nanoseconds
    if ns <= 0 or ns >= 0x7FFFFFFFFFFFFFFF - 1:
        sec, nsec = _INFINITE
    else:
        sec, nsec = divmod(ns, 1_000_000_000)
    return {"sec": int(sec), "nsec": int(nsec)}


def offered_qos_yaml(publishers) -> str:
    import yaml

    profiles = [{
        "history": int(p.qos_profile.history), "depth": int(p.qos_profile.depth),
        "reliability": int(p.qos_profile.reliability), "durability": int(p.qos_profile.durability),
        "deadline": _duration(p.qos_profile.deadline), "lifespan": _duration(p.qos_profile.lifespan),
        "liveliness": int(p.qos_profile.liveliness),
        "liveliness_lease_duration": _duration(p.qos_profile.liveliness_lease_duration),
        "avoid_ros_namespace_conventions": False,
    } for p in publishers]
    return yaml.safe_dump(profiles, sort_keys=False, width=10 ** 9) if profiles else ""


# --- the recorder -------------------------------------------------------------------------
class Recorder:
    """Subscribes to topics as they appear and appends their messages to one MCAP file."""

    def __init__(self, session: Session, folder: str, topics: List[str], record_all: bool):
        from mcap.writer import CompressionType, Writer

        self.session, self.folder, self.record_all = session, folder, record_all
        self.wanted = [absolute_name(t) for t in topics]
        self.file_name = f"{os.path.basename(os.path.normpath(folder))}_0.mcap"
        os.makedirs(folder)
        self._stream = open(os.path.join(folder, self.file_name), "wb")
        self.writer = Writer(self._stream, compression=CompressionType.NONE)
        self.writer.start(profile="ros2", library="ros2py bag record (ball_balance)")
        self.schemas: Dict[str, int] = {}
        self.channels: Dict[str, int] = {}
        self.topic_info: Dict[str, dict] = {}
        self.counts: Dict[str, int] = {}
        self.first_ns: Optional[int] = None
        self.last_ns: Optional[int] = None
        self._subscriptions = []

    def subscribe_new_topics(self) -> None:
        for topic, types in self.session.node.get_topic_names_and_types():
            if topic in self.channels or not types:
                continue
            if not (topic in self.wanted or (self.record_all and not is_hidden(topic))):
                continue
            self._subscribe(topic, types[0])

    def _subscribe(self, topic: str, type_name: str) -> None:
        from ball_balance.cli.messages import get_interface

        publishers = self.session.node.get_publishers_info_by_topic(topic)
        if type_name not in self.schemas:
            self.schemas[type_name] = self.writer.register_schema(
                name=type_name, encoding="ros2msg", data=message_definition(type_name).encode())
        type_hash = str(publishers[0].topic_type_hash) if publishers else ""
        offered = offered_qos_yaml(publishers)
        self.channels[topic] = self.writer.register_channel(
            topic=topic, message_encoding="cdr", schema_id=self.schemas[type_name],
            metadata={"offered_qos_profiles": offered, "topic_type_hash": type_hash})
        self.topic_info[topic] = {"name": topic, "type": type_name, "serialization_format": "cdr",
                                  "offered_qos_profiles": offered, "type_description_hash": type_hash}
        self.counts[topic] = 0
        channel = self.channels[topic]
        self._subscriptions.append(self.session.node.create_subscription(
            get_interface(type_name), topic, lambda data, t=topic, c=channel: self._write(t, c, data),
            self.session.adapted_qos(topic, depth=100), raw=True))

    def _write(self, topic: str, channel: int, data: bytes) -> None:
        now = time.time_ns()
        self.writer.add_message(channel_id=channel, log_time=now, publish_time=now, data=data,
                                sequence=self.counts[topic])
        self.counts[topic] += 1
        self.first_ns = self.first_ns or now
        self.last_ns = now

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def bag_info(self) -> dict:
        """rosbag2's BagMetadata (version 8: QoS policies as integers) for what was recorded."""
        start = self.first_ns or time.time_ns()
        duration = (self.last_ns - self.first_ns) if self.first_ns else 0
        return {
            "version": 8, "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration}, "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": self.total,
            "topics_with_message_count": [{"topic_metadata": self.topic_info[t], "message_count": self.counts[t]}
                                          for t in self.channels],
            "compression_format": "", "compression_mode": "",
            "relative_file_paths": [self.file_name],
            "files": [{"path": self.file_name, "starting_time": {"nanoseconds_since_epoch": start},
                       "duration": {"nanoseconds": duration}, "message_count": self.total}],
            "custom_data": {}, "ros_distro": "jazzy",
        }

    def close(self) -> None:
        """Finish the MCAP file (with rosbag2's 'rosbag2' metadata record) and metadata.yaml."""
        import yaml

        info = self.bag_info()
        # rosbag2's MCAP reader takes the metadata version (and so how to parse the channels'
        # offered_qos_profiles) from this record; ros2 bag reads metadata.yaml in the folder.
        self.writer.add_metadata("rosbag2", {
            "serialized_metadata": yaml.safe_dump(info, sort_keys=False, width=10 ** 9),
            "ROS_DISTRO": "jazzy"})
        self.writer.finish()
        self._stream.close()
        with open(os.path.join(self.folder, "metadata.yaml"), "w", encoding="utf-8") as handle:
            yaml.safe_dump({"rosbag2_bagfile_information": info}, handle, sort_keys=False, width=10 ** 9)


def progress_line(recorder: Recorder, elapsed_s: float, rates: Dict[str, float]) -> str:
    per_topic = "  ".join(f"{t}: {recorder.counts[t]} ({rates.get(t, 0.0):.1f}/s)" for t in recorder.channels)
    waiting = [t for t in recorder.wanted if t not in recorder.channels]
    tail = f"  waiting for: {', '.join(waiting)}" if waiting else ""
    return (f"[{elapsed_s:6.1f} s] {recorder.total} msgs in {len(recorder.channels)} topics  "
            f"{per_topic}{tail}")


def _stop_on_sigterm(signum, frame):
    raise KeyboardInterrupt


def cmd_record(args) -> int:
    if not args.topics and not args.all:
        raise CliError("no topics to record: name them or use -a/--all")
    folder = args.output or time.strftime("rosbag2_%Y_%m_%d-%H_%M_%S")
    if os.path.exists(folder):
        raise CliError(f"output folder '{folder}' already exists: choose another name with -o")
    signal.signal(signal.SIGTERM, _stop_on_sigterm)
    tty = sys.stderr.isatty()
    with Session(args.spin_time) as session:
        recorder = Recorder(session, folder, args.topics, args.all)
        print(f"Recording to '{folder}/{recorder.file_name}' (Ctrl-C to stop)", file=sys.stderr, flush=True)
        start = last_print = time.monotonic()
        last_counts: Dict[str, int] = {}
        try:
            while args.duration is None or time.monotonic() - start < args.duration:
                recorder.subscribe_new_topics()
                session.spin_for(0.2)
                now = time.monotonic()
                if now - last_print >= (1.0 if tty else 5.0):
                    rates = {t: (n - last_counts.get(t, 0)) / (now - last_print) for t, n in recorder.counts.items()}
                    last_counts, last_print = dict(recorder.counts), now
                    line = progress_line(recorder, now - start, rates)
                    print(f"\r\033[K{line}" if tty else line, end="" if tty else "\n", file=sys.stderr, flush=True)
        except KeyboardInterrupt:
            pass
        except Exception as error:  # rclpy shuts the context down on Ctrl-C: end like Ctrl-C
            if type(error).__name__ != "ExternalShutdownException":
                raise
        finally:
            recorder.close()
    print(("\n" if tty else "") + f"Recorded {recorder.total} messages on {len(recorder.channels)} topics "
          f"to '{folder}'", file=sys.stderr, flush=True)
    return 0


def _mcap_files(path: str) -> List[str]:
    if os.path.isdir(path):
        files = sorted(os.path.join(path, f) for f in os.listdir(path) if f.endswith(".mcap"))
        if not files:
            raise CliError(f"no .mcap file in bag folder '{path}'")
        return files
    if not os.path.isfile(path):
        raise CliError(f"bag '{path}' does not exist")
    return [path]


def _stamp(ns: int) -> str:
    return time.strftime("%b %d %Y %H:%M:%S", time.localtime(ns / 1e9)) + f".{ns % 1_000_000_000:09d} " \
        f"({ns // 1_000_000_000}.{ns % 1_000_000_000:09d})"


def cmd_info(args) -> int:
    """Summary of an MCAP bag (folder or file), laid out like `ros2 bag info`."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    files = _mcap_files(args.bag_path)
    topics: Dict[str, list] = {}  # topic -> [type, count, encoding]
    start, end, total, distro = None, None, 0, ""
    for path in files:
        try:
            with open(path, "rb") as stream:
                reader = make_reader(stream)
                summary = reader.get_summary()
                if summary is None or summary.statistics is None:
                    raise CliError(f"'{path}' has no summary section (recording interrupted?)")
                stats = summary.statistics
                for record in reader.iter_metadata():
                    distro = distro or record.metadata.get("ROS_DISTRO", "")
        except (McapError, struct.error, ValueError, EOFError) as error:
            raise CliError(f"'{path}' is not a readable MCAP file: {error}") from None
        if stats.message_count:
            start = min(start or stats.message_start_time, stats.message_start_time)
            end = max(end or stats.message_end_time, stats.message_end_time)
        total += stats.message_count
        for channel_id, channel in summary.channels.items():
            schema = summary.schemas.get(channel.schema_id)
            entry = topics.setdefault(channel.topic, [schema.name if schema else "?", 0, channel.message_encoding])
            entry[1] += stats.channel_message_counts.get(channel_id, 0)
    size = sum(os.path.getsize(p) for p in files)
    duration = ((end or 0) - (start or 0)) / 1e9
    print(f"Files:             {', '.join(os.path.basename(p) for p in files)}")
    print(f"Bag size:          {size / 2 ** 20:.1f} MiB")
    print("Storage id:        mcap")
    print(f"ROS Distro:        {distro or 'unknown'}")
    print(f"Duration:          {duration:.9f}s")
    if start is not None:
        print(f"Start:             {_stamp(start)}")
        print(f"End:               {_stamp(end)}")
    print(f"Messages:          {total}")
    lines = [f"Topic: {t} | Type: {v[0]} | Count: {v[1]} | Serialization Format: {v[2]}" for t, v in topics.items()]
    print("Topic information: " + "\n                   ".join(lines or ["none"]))
    return 0
