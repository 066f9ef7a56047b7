"""`ros2py bag play BAG [--rate R] [--loop] [--topics T...] [--clock [HZ]]`: publish a recorded
MCAP bag again, as `ros2 bag play` does.

Each topic gets a publisher with the QoS its recording publishers offered (reliability,
durability and depth of the first recorded profile; reliable when none was recorded), and
the recorded CDR bytes are published as they are (no decoding). Messages go out in receive
(log) time order, at their recorded spacing divided by --rate. --clock publishes /clock with
the bag's time at HZ (default 40), for nodes with use_sim_time; without it, a recorded
/clock topic is played like any other.

Every chunk is checked as it is read (bag_read.py): a damaged file ends the play with one line
naming the file, where it is damaged and how many messages were played of how many, and exit
code 1.
"""
from __future__ import annotations

import contextlib
import sys
import time
from typing import Dict, List, Optional

from ball_balance.cli.bag_format import (
    DURABILITY,
    RELIABILITY,
    mcap_files,
    parse_offered_qos,
    policy_name,
)
from ball_balance.cli.bag_read import BagDamaged, BagFile
from ball_balance.cli.errors import CliError
from ball_balance.cli.session import Session, StopRequest, valid_name


def publisher_qos(profiles: List[dict]):
    """A publisher QoS like the recorded publishers' (the first profile; reliable, volatile by default)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    reliability, durability, depth = "reliable", "volatile", 10
    if profiles:
        first = profiles[0]
        reliability = policy_name(first.get("reliability", "reliable"), RELIABILITY)
        durability = policy_name(first.get("durability", "volatile"), DURABILITY)
        depth = int(first.get("depth") or depth)
    if reliability not in ("reliable", "best_effort"):
        reliability = "reliable"
    if durability not in ("volatile", "transient_local"):
        durability = "volatile"
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(1, depth),
                      reliability=ReliabilityPolicy[reliability.upper()],
                      durability=DurabilityPolicy[durability.upper()])


class _Channel:
    def __init__(self, topic: str, type_name: str, profiles: List[dict]):
        self.topic, self.type_name, self.profiles = topic, type_name, profiles
        self.publisher = None


def read_channels(summaries: list, selected: Optional[List[str]]) -> Dict[int, _Channel]:
    """(file index, channel id) -> _Channel for the selected topics of the bag's files."""
    channels = {}
    for index, summary in enumerate(summaries):
        for channel_id, channel in summary.channels.items():
            if selected is not None and channel.topic not in selected:
                continue
            schema = summary.schemas.get(channel.schema_id)
            if schema is None or channel.message_encoding != "cdr":
                continue
            channels[(index, channel_id)] = _Channel(
                channel.topic, schema.name, parse_offered_qos(channel.metadata.get("offered_qos_profiles", "")))
    return channels


def bag_time_range(summaries: list) -> tuple:
    """(first, last) log time of the bag's messages (of any topic); --start-offset counts from the first."""
    counted = [s.statistics for s in summaries if s.statistics is not None and s.statistics.message_count]
    return (min((s.message_start_time for s in counted), default=0),
            max((s.message_end_time for s in counted), default=0))


def _messages(bags: List[BagFile], channels: Dict[tuple, _Channel], first_ns: Optional[int] = None):
    """(file index, channel id, log time ns, data) of the messages of `channels` from log time
    first_ns on, in log time order per file; BagDamaged when a file is damaged."""
    for index, bag in enumerate(bags):
        wanted = {channel_id for file_index, channel_id in channels if file_index == index}
        if wanted:
            for channel_id, log_ns, data in bag.messages(wanted, first_ns):
                yield index, channel_id, log_ns, data


def cmd_play(args) -> int:
    with contextlib.ExitStack() as files:
        bags = [files.enter_context(BagFile(path)) for path in mcap_files(args.bag_path)]
        return _play(args, bags)


def _play(args, bags: List[BagFile]) -> int:
    from ball_balance.cli.messages import get_interface

    summaries = [bag.summary for bag in bags]
    selected = [valid_name(t) for t in args.topics] if args.topics else None
    channels = read_channels(summaries, selected)
    if not channels:
        wanted = f" among {', '.join(selected)}" if selected else ""
        raise CliError(f"nothing to play: no recorded topic{wanted} in '{args.bag_path}'")
    topics = sorted({c.topic for c in channels.values()})
    if selected:
        missing = [t for t in selected if t not in topics]
        if missing:
            raise CliError(f"not in the bag: {', '.join(missing)} (it holds: "
                           f"{', '.join(sorted({c.topic for c in read_channels(summaries, None).values()}))})")
    start_ns, end_ns = bag_time_range(summaries)
    if args.start_offset * 1e9 > end_ns - start_ns:
        raise CliError(f"--start-offset {args.start_offset:g} s is past the end of the bag: '{args.bag_path}' is "
                       f"{(end_ns - start_ns) / 1e9:.3f} s long")
    first_ns = start_ns + int(args.start_offset * 1e9) if args.start_offset else None
    expected = sum(bag.message_counts.get(channel_id, 0) for index, bag in enumerate(bags)
                   for file_index, channel_id in channels if file_index == index)
    stop = StopRequest()
    with Session(args.spin_time, name="ros2py_bag_play") as session:
        node = session.node
        publishers = {}
        for channel in channels.values():
            key = (channel.topic, channel.type_name)
            if key not in publishers:
                publishers[key] = node.create_publisher(get_interface(channel.type_name), channel.topic,
                                                        publisher_qos(channel.profiles))
            channel.publisher = publishers[key]
        clock = _ClockPublisher(node, args.clock) if args.clock else None
        print(f"Playing {', '.join(topics)} from '{args.bag_path}' at rate {args.rate:g}"
              f"{' (looping)' if args.loop else ''}; Ctrl-C to stop", file=sys.stderr, flush=True)
        if args.delay > 0:  # let subscribers be discovered before the first message
            session.spin_until(lambda: stop.requested, args.delay)
        played = [0]
        try:
            while not stop.requested:
                _play_once(stop, bags, channels, args.rate, clock, played, args.playback_duration, first_ns)
                if not args.loop:
                    break
        except BagDamaged as error:  # what was played must not look like the whole bag
            raise CliError(f"{error}; played {played[0]} of {expected} messages") from None
    print(f"Played {played[0]} messages", file=sys.stderr, flush=True)
    return 0


class _ClockPublisher:
    """/clock at `rate_hz` with the bag's time while playing (rosbag2's --clock)."""

    def __init__(self, node, rate_hz: float):
        from rclpy.qos import QoSProfile
        from rosgraph_msgs.msg import Clock

        self.msg = Clock()
        self.period_ns = int(1e9 / rate_hz)
        self.publisher = node.create_publisher(Clock, "/clock", QoSProfile(depth=1))
        self.next_ns = None

    def publish(self, bag_ns: int) -> None:
        self.msg.clock.sec, self.msg.clock.nanosec = divmod(bag_ns, 1_000_000_000)
        self.publisher.publish(self.msg)


def _play_once(stop: StopRequest, bags: List[BagFile], channels, rate: float, clock: Optional[_ClockPublisher],
               played: List[int], duration_s: Optional[float] = None, first_ns: Optional[int] = None) -> None:
    """Publish the bag once from log time first_ns (None: its first message), for duration_s
    seconds of it (None: to its end), or until a stop is asked for; the bag's time runs at
    `rate` times the wall clock. Counts the messages published in played[0]."""
    start_wall = time.monotonic_ns()
    start_bag = first_ns
    if clock is not None:
        clock.next_ns = None  # the bag's time starts again (--loop)

    def bag_now() -> int:
        return start_bag + int((time.monotonic_ns() - start_wall) * rate)

    def wait_until(bag_ns: int) -> bool:
        """Wait until the bag's time reaches bag_ns (False) or a stop is asked for (True)."""
        while not stop.requested:
            now = bag_now()
            if clock is not None and (clock.next_ns is None or now >= clock.next_ns):
                # never ahead of the message about to go out: a late wake-up must not move
                # /clock past it (nor past the bag's end)
                clock.publish(min(now, bag_ns))
                clock.next_ns = now + int(clock.period_ns * rate)
            if now >= bag_ns:
                return False
            target = bag_ns if clock is None else min(bag_ns, clock.next_ns)
            stop.sleep_until(time.monotonic() + (target - now) / rate / 1e9)
        return True

    for index, channel_id, log_ns, data in _messages(bags, channels, first_ns):
        channel = channels.get((index, channel_id))
        if channel is None:
            continue
        if start_bag is None:
            start_bag = log_ns
        if duration_s is not None and log_ns - start_bag > duration_s * 1e9:
            break
        if wait_until(log_ns):
            break
        channel.publisher.publish(data)
        played[0] += 1
