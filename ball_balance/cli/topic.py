"""`ros2py topic list|echo|hz|info|pub`, printing as `ros2 topic` does."""
from __future__ import annotations

import math
import sys
import time

from ball_balance.cli.errors import CliError
from ball_balance.cli.session import Session, name_type_pairs, print_name_type_pairs, valid_name


def _session_discovered(args) -> Session:
    session = Session()
    session.discover(args.spin_time)
    return session


def resolve_type(session: Session, topic: str, given: str = None, wait_s: float = 2.0) -> str:
    """The message type of `topic`: `given`, or the one the graph shows (waiting wait_s)."""
    if given:
        return given
    found = session.wait_for_topic_type(topic, wait_s)
    if found is None:
        raise CliError(f"topic '{topic}' not found: nothing publishes or subscribes to it "
                       f"(waited {wait_s:.1f} s; pass the message type to wait for it anyway)")
    return found


def cmd_list(args) -> int:
    with _session_discovered(args) as session:
        pairs = name_type_pairs(session.node.get_topic_names_and_types(), args.include_hidden_topics)
    return print_name_type_pairs(pairs, args.count_topics, args.show_types)


def cmd_echo(args) -> int:
    from ball_balance.cli.messages import echo_text, get_field, get_interface

    topic = valid_name(args.topic_name)
    truncate = None if args.full_length else args.truncate_length
    with Session() as session:
        type_name = resolve_type(session, topic, args.message_type, args.spin_time)
        msg_cls = get_interface(type_name)
        # Give publishers a moment to be discovered so the QoS can be matched to theirs.
        session.spin_until(lambda: session.node.count_publishers(topic) > 0, 1.0)
        qos = session.adapted_qos(topic, _policy(args.qos_reliability), _policy(args.qos_durability),
                                  args.qos_depth)
        received = []

        def on_message(msg):
            value = get_field(msg, args.field) if args.field else msg
            sys.stdout.write(echo_text(value, truncate, args.no_arr, args.no_str) + "---\n")
            sys.stdout.flush()
            if not args.once or not received:
                received.append(True)

        session.node.create_subscription(msg_cls, topic, on_message, qos)
        last = [time.monotonic(), 0]  # time of the last message, messages seen by then

        def finished() -> bool:
            if len(received) > last[1]:
                last[0], last[1] = time.monotonic(), len(received)
                if args.once:
                    return True
            return args.timeout is not None and time.monotonic() - last[0] > args.timeout

        session.spin_until(finished, None, step_s=0.1)
        if not (args.once and received):  # only a --timeout ends an echo without its message
            raise CliError(f"no message on '{topic}' for {args.timeout:.1f} s")
    return 0


def _policy(value):
    return None if value in (None, "system_default") else value


def hz_statistics(intervals_s):
    """(rate_hz, min_s, max_s, std_dev_s) of the receive intervals, as ros2 topic hz shows them."""
    n = len(intervals_s)
    mean = sum(intervals_s) / n
    std_dev = math.sqrt(sum((d - mean) ** 2 for d in intervals_s) / n)
    return 1.0 / mean if mean > 0 else 0.0, min(intervals_s), max(intervals_s), std_dev


def _watch_raw(args, topic: str, on_message, report) -> None:
    """Subscribe `topic` without decoding (QoS matched to its publishers), call on_message(raw)
    for each message and report() once a second, until --duration (or Ctrl-C)."""
    from ball_balance.cli.messages import get_interface

    with Session() as session:
        msg_cls = get_interface(resolve_type(session, topic, None, args.spin_time))
        qos = session.adapted_qos(topic, _policy(args.qos_reliability), _policy(args.qos_durability),
                                  args.qos_depth)
        session.node.create_subscription(msg_cls, topic, on_message, qos, raw=True)
        start = time.monotonic()
        next_report = [start + 1.0]

        def tick() -> bool:
            now = time.monotonic()
            if now >= next_report[0]:
                next_report[0] += 1.0
                report()
            return args.duration is not None and now - start >= args.duration

        session.spin_until(tick, None, step_s=0.05)


def cmd_hz(args) -> int:
    from collections import deque

    stamps = deque(maxlen=args.window + 1)
    count = {"total": 0, "printed_at": 0}

    def on_message(_raw) -> None:
        stamps.append(time.monotonic())
        count["total"] += 1

    def report() -> None:
        if count["total"] == count["printed_at"]:
            if count["total"]:
                print("no new messages", flush=True)
        elif len(stamps) >= 2:
            count["printed_at"] = count["total"]
            samples = list(stamps)
            intervals = [b - a for a, b in zip(samples, samples[1:], strict=False)]
            rate, lo, hi, std = hz_statistics(intervals)
            print(f"average rate: {rate:.3f}\n\tmin: {lo:.3f}s max: {hi:.3f}s "
                  f"std dev: {std:.5f}s window: {len(samples)}", flush=True)

    _watch_raw(args, valid_name(args.topic_name), on_message, report)
    return 0


def bandwidth_text(bytes_per_s: float, count: int, mean: float, smallest: float, largest: float) -> str:
    """ros2 topic bw's two lines: every figure in the unit (B, KB, MB; 1000-based) of the rate."""
    unit, divisor, digits = (("B", 1.0, 0) if bytes_per_s < 1e3 else ("KB", 1e3, 2) if bytes_per_s < 1e6
                             else ("MB", 1e6, 2))

    def text(value: float) -> str:
        return f"{value / divisor:.{digits}f} {unit}"

    return (f"{text(bytes_per_s)}/s from {count} messages\n"
            f"\tMessage size mean: {text(mean)} min: {text(smallest)} max: {text(largest)}")


def cmd_bw(args) -> int:
    from collections import deque

    received = deque(maxlen=args.window)   # (arrival time, size in bytes)

    def on_message(raw: bytes) -> None:
        received.append((time.monotonic(), len(raw)))

    def report() -> None:
        samples = list(received)
        span_s = time.monotonic() - samples[0][0] if len(samples) >= 2 else 0.0
        if span_s > 0.0:
            sizes = [size for _, size in samples]
            print(bandwidth_text(sum(sizes) / span_s, len(sizes), sum(sizes) / len(sizes), min(sizes), max(sizes)),
                  flush=True)

    topic = valid_name(args.topic_name)
    print(f"Subscribed to [{topic}]", flush=True)
    _watch_raw(args, topic, on_message, report)
    return 0


def cmd_info(args) -> int:
    topic = valid_name(args.topic_name)
    with Session() as session:
        type_name = resolve_type(session, topic, None, args.spin_time)
        session.discover(min(args.spin_time, 1.0), settle_s=0.3)
        types = session.topic_types().get(topic, [type_name])
        publishers = session.node.get_publishers_info_by_topic(topic)
        subscriptions = session.node.get_subscriptions_info_by_topic(topic)
    print(f"Type: {'; '.join(types)}")
    if args.verbose:
        print()
    print(f"Publisher count: {len(publishers)}")
    if args.verbose:
        print()
        for info in publishers:
            print(f"{info}\n")
    print(f"Subscription count: {len(subscriptions)}")
    if args.verbose:
        print()
        for info in subscriptions:
            print(f"{info}\n")
    return 0


def cmd_pub(args) -> int:
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from ball_balance.cli.messages import get_interface, parse_yaml_values, set_message_fields, type_name_of

    topic = valid_name(args.topic_name)
    msg_cls = get_interface(args.message_type)
    values = parse_yaml_values(args.values)
    set_message_fields(msg_cls(), values)  # refuse bad values before touching the network
    times = 1 if args.once else args.times
    wait_count = args.wait_matching_subscriptions
    if wait_count is None:
        wait_count = 1 if times else 0
    qos = QoSProfile(
        depth=args.qos_depth,
        reliability=ReliabilityPolicy[(_policy(args.qos_reliability) or "reliable").upper()],
        durability=DurabilityPolicy[(_policy(args.qos_durability) or "volatile").upper()])
    with Session() as session:
        publisher = session.node.create_publisher(msg_cls, topic, qos)
        wanted = type_name_of(msg_cls)

        def other_types() -> list:  # types other endpoints use on this topic (ours is `wanted`)
            return [t for t in session.topic_types().get(topic, []) if t != wanted]

        def graph_type_conflict() -> bool:
            return bool(other_types())

        def ready() -> bool:
            return graph_type_conflict() or publisher.get_subscription_count() >= wait_count

        if wait_count and not session.spin_until(ready, 0.5):   # as ros2 topic pub says it
            print(f"Waiting for at least {wait_count} matching subscription(s)...", flush=True)
        session.spin_until(ready, args.max_wait_time_secs if wait_count else 0.5)
        if not wait_count:
            session.spin_until(graph_type_conflict, 0.3)
        if graph_type_conflict():
            raise CliError(f"topic '{topic}' has type {', '.join(other_types())} on the graph, not {wanted}")
        print("publisher: beginning loop")
        count, period = 0, 1.0 / args.rate
        next_time = time.monotonic()
        while True:
            msg = set_message_fields(msg_cls(), values)
            publisher.publish(msg)
            count += 1
            if args.print_nth and count % args.print_nth == 0:
                print(f"publishing #{count}: {msg}\n", flush=True)
            if times and count >= times:
                break
            next_time += period
            session.spin_for(max(0.0, next_time - time.monotonic()))
        session.spin_for(args.keep_alive)
    return 0
