"""`ros2py bag record -o OUT TOPICS...` and `ros2py bag info BAG`: MCAP bags as rosbag2 (Jazzy)
writes them (the format: bag_format.py), readable by `ros2 bag`, rosbags, Foxglove and
PlotJuggler. `ros2py bag play` is in bag_play.py.

Recording, as rosbag2 does it:
- a topic is subscribed once a publisher is known (topics without one are skipped unless
  --include-unpublished-topics), with a QoS that matches every publisher: reliable only if all
  are, transient local only if all are. The graph is re-read twice a second; when the
  publishers change so that another QoS is needed (a best-effort publisher joins a reliable
  topic), the subscription is made anew;
- every topic's channel carries the offered QoS profiles and the type hash of its publishers
  (metadata.yaml: all profiles seen during the recording);
- the subscriptions are raw (the publisher's CDR bytes, no decoding) with a keep-last depth of
  DEPTH, emptied by a taker thread every TAKE_PERIOD_S that only queues the bytes; a writer
  thread owns the MCAP file and appends them, so writing never delays taking messages out of
  DDS, and the main thread (graph polling, --duration, progress) never waits for the file;
- what is taken but not yet written is bounded (--max-cache-size, as rosbag2's): when the
  writer falls behind, new messages are dropped and counted instead of memory growing;
- a topic whose type is not installed here is skipped with one line, as rosbag2 does; the
  others are recorded;
- a write that fails (disk full, file size limit) stops the recording at once with one line
  naming the error; what was written before it stays in the file.
"""
from __future__ import annotations

import os
import queue
import sys
import threading
import time
from typing import Dict, List, Optional, Set

from ball_balance.cli.bag_format import (
    bag_metadata,
    dump_yaml,
    mcap_files,
    message_definition,
    qos_profile,
    ros_distro_of,
)
from ball_balance.cli.bag_read import BagFile
from ball_balance.cli.errors import CliError
from ball_balance.cli.mcap_write import McapWriter
from ball_balance.cli.messages import get_interface
from ball_balance.cli.session import Session, StopRequest, absolute_name, is_hidden, valid_name
from controller_manager_py.realtime import reuse_freed_memory

# Keep-last depth of the recording subscriptions: how long the taker may stall before a
# topic loses messages (300: 5 s of a 60 Hz camera). Beside one busy process on 2 cores the
# taker still stalls for seconds now and then, longer than a depth of 100 (1.7 s) covers
# (docs/transport.md). Memory is used only while the taker is behind (up to 300 frames: 276 MB
# at 640x480).
DEPTH = 300
POLL_S = 0.5  # how often the graph is re-read for new topics and changed publishers
TAKE_PERIOD_S = 0.005  # how often the subscriptions are emptied (500 Hz topics: 2-3 messages each time)
# At most this many messages of one topic per round: a topic whose messages arrive as fast as a
# starved taker takes them (camera frames on a loaded machine) must not keep the others waiting
# until their keep-last queues overflow (camera_info would be lost that way while frames are kept).
TAKE_BURST = 10
# The taker, the writer and the main thread share the interpreter lock. With the default 5 ms
# switch interval the taker waits whole seconds for it on a loaded machine; at 0.5 ms it takes
# messages tens of milliseconds after publication at the median (docs/transport.md).
SWITCH_INTERVAL_S = 0.0005


def take_waiting(subscription, limit: int):
    """Up to `limit` waiting messages of an rclpy subscription created with `raw=True`, as
    (serialized bytes, message info), without the executor; stops at an empty queue or at a
    subscription destroyed meanwhile (re-matched, unwatched, shutdown)."""
    for _ in range(limit):
        try:
            with subscription.handle:
                taken = subscription.handle.take_message(subscription.msg_type, True)
        except Exception:  # noqa: BLE001 - destroyed meanwhile
            return
        if taken is None:
            return
        yield taken

class WriteCache:
    """Messages taken but not yet written, at most max_bytes of them.

    One thread offers (the taker), one thread gets (the writer); each counts only its own
    bytes, so the two need no lock. A message that would overflow the cache is refused: the
    writer has fallen behind, and a bounded loss beats a recorder that eats the machine's memory.
    An empty cache takes any message, so a message larger than the cache (or any message, with
    max_bytes 0: rosbag2's "no cache") is still recorded when the writer keeps up.
    """

    def __init__(self, max_bytes: int):
        self.max_bytes = max_bytes
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._bytes_in = 0   # taker thread only
        self._bytes_out = 0  # writer thread only

    @property
    def queued_bytes(self) -> int:
        return self._bytes_in - self._bytes_out

    def offer(self, item: tuple, size_bytes: int) -> bool:
        """Queue item (True), or refuse it (False) when it does not fit."""
        if self.queued_bytes > 0 and self.queued_bytes + size_bytes > self.max_bytes:
            return False
        self._bytes_in += size_bytes
        self._queue.put((item, size_bytes))
        return True

    def close(self) -> None:
        """The writer's get() returns None once everything queued before this is written."""
        self._queue.put((None, 0))

    def get(self) -> Optional[tuple]:
        item, size_bytes = self._queue.get()
        self._bytes_out += size_bytes
        return item


def offered_profiles(publishers) -> List[dict]:
    """The publishers' QoS profiles as rosbag2 records them (one per publisher)."""
    return [qos_profile(int(q.history), q.depth, int(q.reliability), int(q.durability), q.deadline.nanoseconds,
                        q.lifespan.nanoseconds, int(q.liveliness), q.liveliness_lease_duration.nanoseconds)
            for q in (p.qos_profile for p in publishers)]


def matching_policies(publishers) -> tuple:
    """(reliability, durability) names of a subscription that matches every publisher."""
    if not publishers:
        return ("best_effort", "volatile")  # matches any publisher that appears later
    reliable = all(p.qos_profile.reliability.name == "RELIABLE" for p in publishers)
    latched = all(p.qos_profile.durability.name == "TRANSIENT_LOCAL" for p in publishers)
    return ("reliable" if reliable else "best_effort", "transient_local" if latched else "volatile")


class _Topic:
    def __init__(self, name: str, type_name: str, interface, definition: str):
        self.name, self.type_name = name, type_name
        # the message class and its ros2msg schema text, resolved when the topic is first seen
        self.interface, self.definition = interface, definition
        self.channel: Optional[int] = None
        self.subscription = None
        self.policies: Optional[tuple] = None
        self.profiles: List[dict] = []
        self.type_hash = ""
        self.count = 0    # written (writer thread)
        self.dropped = 0  # refused by a full cache (taker thread)

    def metadata(self) -> dict:
        return {"name": self.name, "type": self.type_name, "serialization_format": "cdr",
                "offered_qos_profiles": list(self.profiles), "type_description_hash": self.type_hash}


class Recorder:
    """Subscribes to the selected topics as their publishers appear; one MCAP file in `folder`
    (made by cmd_record)."""

    def __init__(self, session: Session, folder: str, topics: List[str], record_all: bool,
                 include_unpublished: bool, max_cache_bytes: int):
        self.session, self.folder, self.record_all = session, folder, record_all
        self.include_unpublished = include_unpublished
        self.wanted = [absolute_name(t) for t in topics]
        self.file_name = f"{os.path.basename(os.path.normpath(folder))}_0.mcap"
        self._stream = open(os.path.join(folder, self.file_name), "wb")
        # The MCAP writer (mcap_write.py: no copies of the messages' bytes), its schemas and
        # channels belong to the writer thread; the main thread touches them only after that
        # thread has ended. A lock shared with the per-message writes would keep the main thread's
        # graph polling, and so --duration, waiting for whole seconds under load.
        self.writer = McapWriter(self._stream)
        self.writer.start(profile="ros2", library="ros2py bag record (ball_balance)")
        self.schemas: Dict[str, int] = {}
        self._lock = threading.Lock()  # topics' offered profiles and type hashes (main and writer thread)
        self.topics: Dict[str, _Topic] = {}
        self.skipped: Set[str] = set()  # topics that cannot be recorded (type not installed)
        self.events: List[str] = []  # lines for the user: subscriptions made and re-matched, topics skipped
        self.write_error: Optional[BaseException] = None  # the first failed write (writer thread)
        self.first_ns: Optional[int] = None
        self.last_ns: Optional[int] = None
        self.cache = WriteCache(max_cache_bytes)
        self.finished = False  # the file's summary and index are written
        self._stop = threading.Event()
        self._spinner = threading.Thread(target=self._take, name="bag-take", daemon=True)
        self._writer_thread = threading.Thread(target=self._drain, name="bag-write", daemon=True)
        self._spinner.start()
        self._writer_thread.start()

    # ---- graph (main thread) -------------------------------------------------------------
    def selected(self, topic: str) -> bool:
        return topic in self.wanted or (self.record_all and not is_hidden(topic))

    def poll(self) -> None:
        """Subscribe to new topics with publishers; re-match the QoS where publishers changed."""
        node = self.session.node
        for name, types in node.get_topic_names_and_types():
            if not types or not self.selected(name) or name in self.skipped:
                continue
            publishers = node.get_publishers_info_by_topic(name)
            topic = self.topics.get(name)
            if topic is None:
                if not publishers and not self.include_unpublished:
                    continue  # as rosbag2: wait for a publisher (its QoS and type hash)
                try:  # as rosbag2: a type not installed here skips its topic, not the recording
                    interface, definition = get_interface(types[0]), message_definition(types[0])
                except CliError as error:
                    self.skipped.add(name)
                    self.events.append(f"skipping topic '{name}': {error}")
                    continue
                topic = self.topics[name] = _Topic(name, types[0], interface, definition)
            self._learn(topic, publishers)
            wanted = matching_policies(publishers)
            if topic.policies != wanted and (publishers or topic.subscription is None):
                if topic.subscription is None:
                    self.events.append(f"Subscribed to topic '{name}' ({'/'.join(wanted)})")
                else:
                    self.events.append(f"re-matched the QoS of {name}: {'/'.join(topic.policies)} -> "
                                       f"{'/'.join(wanted)} (publishers changed)")
                self._subscribe(topic, wanted)

    def _learn(self, topic: _Topic, publishers) -> None:
        with self._lock:
            for profile in offered_profiles(publishers):
                if profile not in topic.profiles:
                    topic.profiles.append(profile)
            if publishers and not topic.type_hash:
                topic.type_hash = str(publishers[0].topic_type_hash)

    def _register(self, topic: _Topic) -> None:
        """The topic's schema and channel, with what its publishers offer (writer thread)."""
        if topic.type_name not in self.schemas:
            self.schemas[topic.type_name] = self.writer.register_schema(
                name=topic.type_name, encoding="ros2msg", data=topic.definition.encode())
        with self._lock:
            metadata = {"offered_qos_profiles": dump_yaml(topic.profiles) if topic.profiles else "",
                        "topic_type_hash": topic.type_hash}
        topic.channel = self.writer.register_channel(
            topic=topic.name, message_encoding="cdr", schema_id=self.schemas[topic.type_name], metadata=metadata)

    def _subscribe(self, topic: _Topic, policies: tuple) -> None:
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        node = self.session.node
        if topic.subscription is not None:
            node.destroy_subscription(topic.subscription)
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEPTH,
                         reliability=ReliabilityPolicy[policies[0].upper()],
                         durability=DurabilityPolicy[policies[1].upper()])
        # No callback: the taker thread takes the messages (on_message is never called).
        topic.subscription = node.create_subscription(topic.interface, topic.name,
                                                      lambda data: None, qos, raw=True)
        topic.policies = policies

    # ---- threads ---------------------------------------------------------------------------
    def _take(self) -> None:
        """Taker thread: every TAKE_PERIOD_S, take the waiting messages of every topic in turn.

        rclpy's executor costs tens of microseconds per wake-up and callback; at the simulated
        graph's ~1500 messages/s that keeps the recorder's DDS receive thread from the CPU on a
        loaded machine, and camera frames are lost where a plain subscriber of the camera alone
        keeps them all. Polling the subscriptions costs a C call per message; the keep-last DEPTH
        queues absorb the period."""
        offer = self.cache.offer
        while not self._stop.is_set():
            started = time.monotonic()
            for topic in list(self.topics.values()):
                subscription = topic.subscription
                if subscription is None:
                    continue
                for data, info in take_waiting(subscription, TAKE_BURST):
                    if not offer((topic, data, time.time_ns(), info.get("source_timestamp", 0)), len(data)):
                        topic.dropped += 1
            self._stop.wait(max(0.0, TAKE_PERIOD_S - (time.monotonic() - started)))

    def _drain(self) -> None:
        while True:
            item = self.cache.get()
            if item is None:
                return
            if self.write_error is not None:  # discard: the cache must not fill while the main thread stops
                continue
            try:
                self._write(*item)
            except Exception as error:  # noqa: BLE001 - disk full, file size limit, ...: reported by the main thread
                self.write_error = error

    def _write(self, topic: _Topic, data: bytes, receive_ns: int, source_ns: int) -> None:
        if topic.channel is None:
            if not topic.type_hash:  # an unpublished topic's first message: its publisher is known now
                self._learn(topic, self.session.node.get_publishers_info_by_topic(topic.name))
            self._register(topic)
        self.writer.add_message(channel_id=topic.channel, log_time=receive_ns,
                                publish_time=source_ns or receive_ns, data=data, sequence=topic.count)
        topic.count += 1
        self.first_ns = self.first_ns or receive_ns
        self.last_ns = receive_ns

    # ---- results ---------------------------------------------------------------------------
    @property
    def recorded(self) -> List[_Topic]:
        """The topics subscribed (or written) so far."""
        return [t for t in self.topics.values() if t.channel is not None or t.subscription is not None]

    @property
    def total(self) -> int:
        return sum(t.count for t in self.topics.values())

    @property
    def dropped(self) -> int:
        return sum(t.dropped for t in self.topics.values())

    def bag_info(self) -> dict:
        recorded = [t for t in self.topics.values() if t.channel is not None]
        start = self.first_ns or time.time_ns()
        duration = (self.last_ns - self.first_ns) if self.first_ns else 0
        return bag_metadata(self.file_name, [t.metadata() for t in recorded], [t.count for t in recorded],
                            start, duration)

    def close(self) -> None:
        """Stop taking messages, write what is queued, finish the file and metadata.yaml."""
        self._stop.set()
        self._spinner.join(timeout=2.0)
        for topic in self.topics.values():
            if topic.subscription is not None:
                try:
                    self.session.node.destroy_subscription(topic.subscription)
                except Exception:  # noqa: BLE001 - the context may already be shut down (Ctrl-C)
                    pass
        self.cache.close()
        self._writer_thread.join()
        try:
            for topic in self.recorded:  # subscribed, no message written: listed with a count of 0
                if topic.channel is None and topic.type_hash:
                    self._register(topic)
            info = self.bag_info()
            # rosbag2's MCAP reader takes the metadata version (and so how to parse the channels'
            # offered_qos_profiles) from this record; `ros2 bag` reads metadata.yaml in the folder.
            self.writer.add_metadata("rosbag2", {"serialized_metadata": dump_yaml(info)})
            self.writer.finish()
            self._stream.close()
            self.finished = True
            with open(os.path.join(self.folder, "metadata.yaml"), "w", encoding="utf-8") as handle:
                handle.write(dump_yaml({"rosbag2_bagfile_information": info}))
        except OSError as error:
            self.write_error = self.write_error or error
            try:
                self._stream.close()  # releases the file even when its last flush fails
            except OSError:
                pass
        if self.write_error is not None:
            raise CliError(self._write_error_text()) from None

    def _write_error_text(self) -> str:
        error = self.write_error
        reason = (f"{error.strerror} (errno {error.errno})" if isinstance(error, OSError) and error.strerror
                  else f"{type(error).__name__}: {error}")
        path = os.path.join(self.folder, self.file_name)
        if self.finished:
            kept = f"The {self.total} messages written before it are in the bag"
        else:
            kept = (f"The {self.writer.messages_in_file} messages written before it are in the file, which has "
                    f"no summary or index (the MCAP tool's `mcap recover` rebuilds them)")
        return f"recording stopped: cannot write '{path}': {reason}. {kept}"


def progress_line(recorder: Recorder, elapsed_s: float, rates: Dict[str, float]) -> str:
    per_topic = "  ".join(f"{t.name}: {t.count} ({rates.get(t.name, 0.0):.1f}/s)" for t in recorder.recorded)
    waiting = [t for t in recorder.wanted if t not in recorder.topics]
    tail = f"  waiting for a publisher on: {', '.join(waiting)}" if waiting else ""
    if recorder.dropped:
        tail += f"  lost {recorder.dropped} (the writer is behind: cache of {recorder.cache.max_bytes} bytes full)"
    return (f"[{elapsed_s:6.1f} s] {recorder.total} msgs in {len(recorder.recorded)} topics  "
            f"{per_topic}{tail}")


def cmd_record(args) -> int:
    if not args.topics and not args.all:
        raise CliError("no topics to record: name them or use -a/--all")
    topics = [valid_name(t) for t in args.topics]
    folder = args.output or time.strftime("rosbag2_%Y_%m_%d-%H_%M_%S")
    if os.path.exists(folder):
        raise CliError(f"output folder '{folder}' already exists: choose another name with -o")
    try:  # before any node: a parent that is a file, no permission, a full disk
        os.makedirs(folder)
    except OSError as error:
        raise CliError(f"cannot create the bag folder {folder}: {error.strerror}") from None
    stop = StopRequest()
    tty = sys.stderr.isatty()
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    # a frame's bytes per take, freed once written: from reused heap pages instead of a fresh
    # mapping per frame (about 30 us less CPU per 640x480 frame's take)
    reuse_freed_memory()
    with Session(args.spin_time) as session:
        recorder = Recorder(session, folder, topics, args.all, args.include_unpublished_topics,
                            args.max_cache_size)
        print(f"Recording to '{folder}/{recorder.file_name}' (Ctrl-C to stop)", file=sys.stderr, flush=True)
        start = last_print = time.monotonic()
        last_counts: Dict[str, int] = {}
        try:
            while args.duration is None or time.monotonic() - start < args.duration:
                if not session.context.ok() or recorder.write_error is not None:
                    break
                recorder.poll()
                while recorder.events:
                    print(recorder.events.pop(0), file=sys.stderr, flush=True)
                end = time.monotonic() + POLL_S
                if args.duration is not None:
                    end = min(end, start + args.duration)
                if stop.sleep_until(end):
                    break
                now = time.monotonic()
                if now - last_print >= (1.0 if tty else 5.0):
                    counts = {t.name: t.count for t in recorder.recorded}
                    rates = {t: (n - last_counts.get(t, 0)) / (now - last_print) for t, n in counts.items()}
                    last_counts, last_print = counts, now
                    line = progress_line(recorder, now - start, rates)
                    print(f"\r\033[K{line}" if tty else line, end="" if tty else "\n", file=sys.stderr, flush=True)
        finally:
            recorder.close()
    lost = recorder.dropped
    lost_text = f"; {lost} lost while the writer was behind (--max-cache-size)" if lost else ""
    print(("\n" if tty else "") + f"Recorded {recorder.total} messages on {len(recorder.recorded)} topics "
          f"to '{folder}'{lost_text}", file=sys.stderr, flush=True)
    return 0


def _stamp(ns: int) -> str:
    return time.strftime("%b %d %Y %H:%M:%S", time.localtime(ns / 1e9)) + f".{ns % 1_000_000_000:09d} " \
        f"({ns // 1_000_000_000}.{ns % 1_000_000_000:09d})"


def cmd_info(args) -> int:
    """Summary of an MCAP bag (folder or file), laid out like `ros2 bag info`."""
    files = mcap_files(args.bag_path)
    summaries, distro = [], ""
    for path in files:  # every record checked before anything is printed: a damaged file is one line
        with BagFile(path) as bag:
            metadata = bag.check()
        summaries.append(bag.summary)
        distro = distro or ros_distro_of(metadata)
    topics: Dict[str, list] = {}  # topic -> [type, count, encoding]
    start, end, total = None, None, 0
    for path, summary in zip(files, summaries, strict=True):
        stats = summary.statistics
        if stats is None:
            raise CliError(f"'{path}' has no statistics in its summary (not written by a complete recording?)")
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
