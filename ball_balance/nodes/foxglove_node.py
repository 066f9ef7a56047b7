"""`ball_balance_foxglove`: the graph's topics over the Foxglove WebSocket protocol (docs/foxglove.md).

Foxglove or Lichtblick connect to ws://127.0.0.1:8765 (`host`, `port`) and see the topics named
in `topics` as the ROS graph carries them:
- one channel per topic, advertised once the topic has a publisher: message encoding `cdr`
  (the publisher's bytes, never decoded here), schema `ros2msg` named `pkg/msg/Type`, the .msg
  text of the installed interface package with its nested types appended (the schema rosbag2
  writes, ball_balance.cli.bag_format);
- a topic is subscribed only while a client watches its channel (ball_balance.foxglove_relay),
  with a QoS that matches every publisher (reliable only if all are, transient local only if
  all are), re-matched when the publishers change;
- images (sensor_msgs Image, CompressedImage) at most `max_image_rate_hz` frames a second;
- time: while /clock has a publisher (simulated time), the server sends its clients the graph's
  time from /clock (the protocol's `time` capability) and stamps every message it forwards
  with it; otherwise messages carry the wall-clock time they arrived.
The Foxglove SDK (`foxglove-sdk`) runs the server on its own threads; its client events come
here through a queue and a guard condition, so the graph and the subscriptions are handled on
the executor's thread. The messages are not: the subscriptions belong to a hidden node no
executor spins, and a thread of their own (_Taker) empties them and hands the bytes to the SDK.
"""
from __future__ import annotations

import queue
import threading
import time
from typing import Dict, Optional

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from ball_balance.cli.bag import matching_policies, take_waiting
from ball_balance.cli.bag_format import message_definition
from ball_balance.cli.errors import CliError
from ball_balance.cli.messages import get_interface
from ball_balance.foxglove_relay import (
    RESUBSCRIBE,
    SUBSCRIBE,
    UNSUBSCRIBE,
    RateLimit,
    Watchers,
    clock_ns,
    is_image,
    topic_list_problem,
)
from controller_manager_py.parameters import Param, declare_parameters
from controller_manager_py.ros.node_main import StartupError, main_for

DEFAULT_TOPICS = ("/camera/image_raw", "/camera/camera_info", "/tf", "/tf_static", "/ball_balance_visualization",
                  "/ball_state", "/joint_states", "/diagnostics", "/ball_reference", "/plate_cmd",
                  "/robot_description")

SCHEMA = [
    Param("host", "127.0.0.1", "address the WebSocket server listens on (0.0.0.0: every interface)",
          read_only=True, user_facing=True),
    Param("port", 8765, "WebSocket port (0: a free one, named in the start-up line)", "", 0, 65535,
          read_only=True, user_facing=True),
    Param("topics", DEFAULT_TOPICS, "topics served, each once it has a publisher", read_only=True,
          user_facing=True, check=topic_list_problem),
    Param("max_image_rate_hz", 15.0, "frames a second at most, per image topic (0: every frame)", "Hz",
          0.0, 1000.0, read_only=True, user_facing=True),
    Param("graph_poll_s", 1.0, "how often the ROS graph is read for new topics and changed publishers", "s",
          0.1, 10.0, read_only=True),
]
DEPTH = 10  # keep-last depth of the subscriptions: several latched /tf_static publishers fit
CLOCK_TOPIC = "/clock"
TAKE_PERIOD_S = 0.01  # how often the watched subscriptions are emptied (the delay it adds: at most this)
TAKE_BURST = 10  # at most this many messages of one topic per round: a camera must not hold up the others


def _qos(policies: tuple, depth: int) -> QoSProfile:
    reliability, durability = policies
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy[reliability.upper()],
                      durability=DurabilityPolicy[durability.upper()])


class _ServerTime:
    """The graph's simulated time from /clock (ns), or None: the wall clock (the SDK's default)."""

    ns: Optional[int] = None


class _Topic:
    """One served topic: its Foxglove channel once advertised, its subscription while watched."""

    def __init__(self, name: str):
        self.name = name
        self.type_name: Optional[str] = None
        self.interface = None
        self.channel = None
        self.policies: Optional[tuple] = None  # (reliability, durability) matching the publishers
        self.subscription = None
        self.forward = None  # the bytes of one message -> the channel (rate-limited for images)
        self.limit: Optional[RateLimit] = None

    @property
    def latched(self) -> bool:
        return self.policies is not None and self.policies[1] == "transient_local"


class _Taker:
    """A thread that empties the watched topics' subscriptions every TAKE_PERIOD_S and hands each
    message's bytes to its topic's forwarder; it sleeps while no topic is watched.

    Why not subscription callbacks: rclpy's executor costs a wait-set rebuild and a Python
    round trip per message. With 100 Hz /joint_states and /tf watched (200 small messages a
    second), callbacks cost the node about three times the CPU that taking the messages this way
    does; `ros2py bag record` takes its messages the same way for the same reason.
    """

    def __init__(self):
        self.routes: tuple = ()  # ((subscription, forward), ...): replaced whole by the executor thread
        self._wake, self._stop = threading.Event(), threading.Event()
        self._thread = threading.Thread(target=self._run, name="foxglove-take", daemon=True)
        self._thread.start()

    def route(self, routes) -> None:
        self.routes = tuple(routes)
        self._wake.set()

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        self._thread.join(timeout=2.0)

    def _run(self) -> None:
        while not self._stop.is_set():
            routes = self.routes
            if not routes:
                self._wake.wait()
                self._wake.clear()
                continue
            started = time.monotonic()
            for subscription, forward in routes:
                for data, _ in take_waiting(subscription, TAKE_BURST):
                    forward(data)
            self._stop.wait(max(0.0, TAKE_PERIOD_S - (time.monotonic() - started)))


class _ClientEvents:
    """The SDK's server listener: queues client (un)subscriptions and wakes the executor."""

    def __init__(self, events: queue.SimpleQueue, wake):
        self.events, self.wake = events, wake

    def on_subscribe(self, client, channel) -> None:
        self.events.put((True, channel.id, client.id))
        self.wake.trigger()

    def on_unsubscribe(self, client, channel) -> None:
        self.events.put((False, channel.id, client.id))
        self.wake.trigger()


class FoxgloveNode(Node):
    def __init__(self):
        super().__init__("ball_balance_foxglove")
        self.params = declare_parameters(self, SCHEMA)
        import foxglove

        self.foxglove = foxglove
        self.topics: Dict[str, _Topic] = {name: _Topic(name) for name in self.params["topics"]}
        self.by_channel: Dict[int, _Topic] = {}
        self.watchers = Watchers()
        self.events: queue.SimpleQueue = queue.SimpleQueue()
        self.wake = self.create_guard_condition(self.on_client_events)
        self.time = _ServerTime()
        self.clock_publishers: list = []
        self.clock_subscription = None
        self.bad_clocks = 0
        host, port = self.params["host"], self.params["port"]
        from foxglove.websocket import Capability

        try:
            self.server = foxglove.start_server(name="ball_balance", host=host, port=port,
                                                capabilities=[Capability.Time],
                                                server_listener=_ClientEvents(self.events, self.wake))
        except Exception as error:  # noqa: BLE001 - the SDK raises RuntimeError for a busy or bad address
            raise StartupError(f"cannot serve on {host}:{port}: {error}") from None
        # hidden (leading underscore) and never spun: the taker empties its subscriptions. Without
        # the command line's arguments, so that a `__node:=` remap names the main node only.
        self.reader = Node("_ball_balance_foxglove_reader", context=self.context, use_global_arguments=False,
                           start_parameter_services=False, enable_rosout=False)
        self.taker = _Taker()
        self.create_timer(self.params["graph_poll_s"], self.on_graph_poll)
        self.on_graph_poll()

    def announce(self) -> None:
        """The start-up line (controller_manager_py.ros.node_main.run_node)."""
        self.get_logger().info(f"Foxglove WebSocket server on ws://{self.params['host']}:{self.server.port} "
                               f"({len(self.topics)} topics, each once it has a publisher)")

    # ---- graph (executor thread) ----------------------------------------------------------------
    def on_graph_poll(self) -> None:
        """Advertise topics that got a publisher; re-match the QoS where the publishers changed."""
        types = dict(self.get_topic_names_and_types())
        self.clock_publishers = self.get_publishers_info_by_topic(CLOCK_TOPIC) if CLOCK_TOPIC in types else []
        self.follow_clock()
        for topic in list(self.topics.values()):  # advertise() drops a topic it cannot serve
            if not types.get(topic.name):
                continue
            publishers = self.get_publishers_info_by_topic(topic.name)
            if not publishers:
                continue  # its QoS is not known yet: wait, as rosbag2 does
            if topic.channel is None and not self.advertise(topic, types[topic.name][0]):
                continue
            policies = matching_policies(publishers)
            if policies != topic.policies:
                topic.policies = policies
                if topic.subscription is not None:
                    self.get_logger().info(f"re-matched the QoS of {topic.name}: {'/'.join(policies)}")
                    self.subscribe(topic)

    def advertise(self, topic: _Topic, type_name: str) -> bool:
        try:
            topic.interface = get_interface(type_name)
            definition = message_definition(type_name)
        except CliError as error:
            self.get_logger().error(f"not serving {topic.name}: {error}")
            del self.topics[topic.name]
            return False
        schema = self.foxglove.Schema(name=type_name, encoding="ros2msg", data=definition.encode())
        topic.type_name = type_name
        topic.channel = self.foxglove.Channel(topic.name, message_encoding="cdr", schema=schema)
        topic.limit = RateLimit(self.params["max_image_rate_hz"]) if is_image(type_name) else None
        self.by_channel[topic.channel.id()] = topic
        self.get_logger().info(f"advertised {topic.name} ({type_name})")
        return True

    # ---- clients (executor thread, woken by the SDK's listener) -----------------------------------
    def on_client_events(self) -> None:
        while True:
            try:
                subscribed, channel_id, client_id = self.events.get_nowait()
            except queue.Empty:
                return
            topic = self.by_channel.get(channel_id)
            if topic is None:
                continue
            if subscribed:
                action = self.watchers.joined(channel_id, client_id, topic.latched)
            else:
                action = self.watchers.left(channel_id, client_id)
            if action in (SUBSCRIBE, RESUBSCRIBE):
                self.subscribe(topic)
            elif action == UNSUBSCRIBE:
                self.unsubscribe(topic)

    def follow_clock(self) -> None:
        """Subscribe to /clock while it has a publisher; without one, the wall clock.

        Subscribed even while no client watches: DDS keeps the newest time in the reader (depth
        1) at no cost to Python, and when a client starts watching, the taker's first round
        takes that time before any message it forwards. The taker takes /clock only while some
        client watches (reroute)."""
        wanted = bool(self.clock_publishers)
        if wanted == (self.clock_subscription is not None):
            return
        if wanted:
            qos = _qos(matching_policies(self.clock_publishers), depth=1)  # only the newest time matters
            self.clock_subscription = self.reader.create_subscription(Clock, CLOCK_TOPIC, lambda data: None, qos,
                                                                      raw=True)
            self.get_logger().info("following /clock: clients get the graph's simulated time")
        else:
            self.reader.destroy_subscription(self.clock_subscription)
            self.clock_subscription = None
            self.time.ns = None
            self.get_logger().info("/clock has no publisher: clients get the wall-clock time")
        self.reroute()

    def on_clock(self, data: bytes) -> None:
        """The taker's /clock route: the graph's time to the clients and to what is forwarded."""
        try:
            self.time.ns = clock_ns(data)
        except ValueError as error:
            self.bad_clocks += 1
            self.get_logger().error(f"{error} ({self.bad_clocks} so far)", throttle_duration_sec=10.0)
            return
        self.server.broadcast_time(self.time.ns)

    def subscribe(self, topic: _Topic) -> None:
        """(Re)create the topic's subscription with its publishers' policies."""
        self.unsubscribe(topic)
        qos = _qos(topic.policies, DEPTH)
        # no callback: the taker takes the messages (the reader node is never spun)
        topic.subscription = self.reader.create_subscription(topic.interface, topic.name, lambda data: None, qos,
                                                             raw=True)
        topic.forward = self.forwarder(topic)
        self.reroute()

    def unsubscribe(self, topic: _Topic) -> None:
        if topic.subscription is not None:
            self.reader.destroy_subscription(topic.subscription)
            topic.subscription = None
            self.reroute()

    def reroute(self) -> None:
        """The taker's routes: /clock first (while a client watches), so that a round's messages
        carry its newest time."""
        following = self.clock_subscription is not None and self.watchers.any
        clock = [(self.clock_subscription, self.on_clock)] if following else []
        self.taker.route(clock + [(t.subscription, t.forward) for t in self.topics.values()
                                  if t.subscription is not None])

    def forwarder(self, topic: _Topic):
        """What the taker calls per message: the CDR bytes to the channel, nothing else."""
        log, limit, clock = topic.channel.log, topic.limit, self.time
        if limit is None:
            return lambda data: log(data, log_time=clock.ns)
        return lambda data: log(data, log_time=clock.ns) if limit.allow(time.monotonic_ns()) else None

    def destroy_node(self) -> None:
        self.taker.stop()
        self.server.stop()
        self.reader.destroy_node()
        super().destroy_node()


main = main_for(FoxgloveNode)
