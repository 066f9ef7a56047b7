"""`ball_balance_live_view`: the live view in the browser (docs/live_view.md).

Serves http://127.0.0.1:8080/ (`host`, `port`): the camera image with the tracker's detection
drawn over it, the plate from above with the ball, the reference and the recent path, the
error over the last seconds, the controller's and the robot manager's state; and buttons for
the robot manager's lifecycle (configure, activate, deactivate), its emergency stop and reset,
the reference and the controller's gains.

Threads and cost. One single-threaded executor runs this node. The web server (aiohttp) runs
on an asyncio loop in a thread of its own (ball_balance.live_view.server), the JPEG encoder in
another (ball_balance.live_view.frames). Nothing is subscribed at the camera's or the ball
state's rate while nobody looks: the high-rate topics (/ball_state, /ball_reference,
/joint_states, the camera) are subscriptions of a hidden node that no executor spins, created
when the first page connects and destroyed when the last leaves. A `GET /api/state` (a script)
follows the ball, the reference and the arm too, not the camera, until API_FOLLOW_S after the
last such request. A timer at `update_rate_hz` takes what they hold (no callback per message),
updates the model and, while a page is connected, pushes one state to the pages; the encoder
thread takes the newest frame itself at most `image_rate_hz` times a second. `/api/state` gets a
state built for it on the executor from the newest messages (the first request after a quiet
spell waits at most FIRST_STATE_WAIT_S for the first ball state), never one kept from a page.

Requests from the page arrive on the web thread, are checked there (live_view.commands), and
cross to the executor through a queue and a guard condition. Every service call has a deadline
(`call_timeout_s`): an absent service is answered at once ("... is not available"), one that
does not answer in time is dropped and answered so; the executor never waits for a reply.
"""
from __future__ import annotations

import concurrent.futures
import math
import queue
import time
from typing import Callable, List, Optional

from ball_tracker_msgs.msg import BallState
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PointStamped
from lifecycle_msgs.msg import TransitionEvent
from lifecycle_msgs.srv import ChangeState, GetState
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import Bool
from std_srvs.srv import Trigger

from ball_balance.live_view import commands
from ball_balance.live_view.frames import FrameEncoder
from ball_balance.live_view.model import Ball, LiveModel
from ball_balance.live_view.server import LiveViewServer
from ball_balance.ros.images import decode_image, image_from_cdr
from controller_manager_py.manager.throttle import Throttle
from controller_manager_py.parameters import Param, declare_parameters
from controller_manager_py.ros.node_main import StartupError, main_for

SCHEMA = [
    Param("host", "127.0.0.1", "address the web server listens on (0.0.0.0: every interface; the page "
          "controls the arm, so prefer an ssh tunnel, docs/live_view.md)", read_only=True, user_facing=True),
    Param("port", 8080, "web server port (0: a free one, named in the start-up line)", "", 0, 65535,
          read_only=True, user_facing=True),
    Param("image_topic", "/camera/image_raw", "camera frames shown (bgr8 or rgb8); the tracker's "
          "/ball_tracker/debug_image (publish_debug_image) shows its own overlay", read_only=True, user_facing=True),
    Param("image_rate_hz", 15.0, "camera frames sent to the pages a second at most (15: a quarter of the "
          "simulated 60 Hz camera)", "Hz", 0.5, 60.0, read_only=True, user_facing=True),
    Param("image_scale", 1.0, "frames are resized by this factor before JPEG encoding", "", 0.1, 1.0,
          read_only=True),
    Param("jpeg_quality", 70, "JPEG quality of the frames sent", "", 10, 100, read_only=True),
    Param("update_rate_hz", 10.0, "state updates sent to the pages a second", "Hz", 1.0, 60.0, read_only=True),
    Param("error_window_s", 10.0, "the error plot shows this many seconds", "s", 1.0, 120.0, read_only=True),
    Param("path_window_s", 3.0, "the plate view shows the ball's path over this many seconds", "s", 0.5, 60.0,
          read_only=True),
    Param("controller_node", "ball_balance_controller", "the balance controller node whose gains and "
          "reference the page shows and sets", read_only=True, user_facing=True),
    Param("gain_names", ["kp", "ki", "kd"], "the controller's parameters shown and set as its gains",
          read_only=True),
    Param("robot_manager_node", "robot_manager", "the lifecycle robot manager the page controls",
          read_only=True),
    Param("call_timeout_s", 3.0, "deadline of every service call made for the page", "s", 0.1, 60.0,
          read_only=True),
]
# what the reader keeps between two updates: a 60 Hz ball state and reference at the 10 Hz update
KEPT = 20
BALL_QOS = QoSProfile(depth=KEPT, reliability=qos_profile_sensor_data.reliability,
                      durability=qos_profile_sensor_data.durability)
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)
REFERENCE_PARAMS = ("reference_kind", "reference_centre_m", "reference_radius_m", "reference_period_s")
POLL_PERIOD_S = 1.0         # the robot manager's state and the controller's parameters, while watched
DEADLINE_CHECK_S = 0.05     # how often pending calls are checked against their deadline
TAKE_LIMIT = 100            # messages taken from one topic per update at most
FRESH_S = 1.0               # a topic silent (wall clock) this long is shown as stale
API_FOLLOW_S = 10.0         # after a GET /api/state the ball, reference and arm are followed this long
FIRST_STATE_WAIT_S = 2.0    # a GET /api/state that starts following waits this long at most for a ball state
LOG_PERIOD_S = 5.0          # a page's requests and refused input: one line per kind this often at most


def _stamp_s(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def _value(value: ParameterValue):
    """A ParameterValue -> plain Python (None for types the page does not show)."""
    return {ParameterType.PARAMETER_DOUBLE: lambda v: v.double_value,
            ParameterType.PARAMETER_INTEGER: lambda v: v.integer_value,
            ParameterType.PARAMETER_STRING: lambda v: v.string_value,
            ParameterType.PARAMETER_BOOL: lambda v: v.bool_value,
            ParameterType.PARAMETER_DOUBLE_ARRAY: lambda v: list(v.double_array_value)}.get(
        value.type, lambda v: None)(value)


def _parameter(name: str, value) -> Parameter:
    if isinstance(value, str):
        pv = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value)
    elif isinstance(value, list):
        pv = ParameterValue(type=ParameterType.PARAMETER_DOUBLE_ARRAY, double_array_value=[float(v) for v in value])
    else:
        pv = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=float(value))
    return Parameter(name=name, value=pv)


def _take(subscription, limit: int = TAKE_LIMIT) -> List:
    """The messages waiting in a subscription of the unspun reader node (oldest first)."""
    taken = []
    for _ in range(limit):
        try:
            with subscription.handle:
                message = subscription.handle.take_message(subscription.msg_type, subscription.raw)
        except Exception:  # noqa: BLE001 - destroyed meanwhile (shutdown)
            break
        if message is None:
            break
        taken.append(message[0])
    return taken


class _Pending:
    """A service call made for the page, answered by its reply or by its deadline."""

    def __init__(self, client, future, answer: concurrent.futures.Future, what: str, deadline: float):
        self.client, self.future, self.answer, self.what, self.deadline = client, future, answer, what, deadline


class LiveViewNode(Node):
    def __init__(self):
        super().__init__("ball_balance_live_view")
        self.params = declare_parameters(self, SCHEMA)
        p = self.params
        self.model = LiveModel(p["error_window_s"], p["path_window_s"])
        self.model.controller["node"] = p["controller_node"]
        self.model.image.update(topic=p["image_topic"], rate_hz=p["image_rate_hz"], scale=p["image_scale"])
        self.gain_names = tuple(p["gain_names"])
        self.allowed = self.gain_names
        manager, controller = "/" + p["robot_manager_node"].strip("/"), "/" + p["controller_node"].strip("/")
        self.manager_name, self.controller_name = manager, controller
        self.change_state = self.create_client(ChangeState, f"{manager}/change_state")
        self.get_state = self.create_client(GetState, f"{manager}/get_state")
        self.triggers = {op: self.create_client(Trigger, f"{manager}/{op}") for op in commands.TRIGGERS}
        self.set_params = self.create_client(SetParameters, f"{controller}/set_parameters")
        self.get_params = self.create_client(GetParameters, f"{controller}/get_parameters")
        self.pending: List[_Pending] = []
        self.polling = {"state": False, "params": False}   # a poll call is under way
        # always subscribed: rare messages the page must show as soon as it opens
        self.create_subscription(Bool, f"{manager}/emergency_stop_active", self.on_estop, LATCHED)
        self.create_subscription(DiagnosticStatus, f"{manager}/events", self.on_event, 10)
        self.create_subscription(TransitionEvent, f"{manager}/transition_event", self.on_transition, 10)
        self.create_subscription(DiagnosticArray, "/diagnostics", self.on_diagnostics, 10)
        # the high-rate topics: subscribed on the unspun reader only while a page or a script looks (watch)
        self.reader = Node("_ball_balance_live_view_reader", context=self.context, use_global_arguments=False,
                           start_parameter_services=False, enable_rosout=False)
        self.watched: Optional[dict] = None
        self.asked_s = -math.inf                # (monotonic) the last GET /api/state
        self.following_since = -math.inf        # (monotonic) the ball state subscription's creation
        self.ball_taken = False                 # a ball state was taken since then
        self.state_requests: queue.SimpleQueue = queue.SimpleQueue()
        self.state_waiting: List[concurrent.futures.Future] = []
        self.wall = {"ball": -math.inf, "joints": -math.inf}
        self.pages = 0
        self.refused_requests = 0               # a page's request refused, not JSON, a malformed HTTP request
        self.throttle = Throttle(self.get_logger(), LOG_PERIOD_S)
        self.requests: queue.SimpleQueue = queue.SimpleQueue()
        self.wake = self.create_guard_condition(self.on_wake)
        self.encoder = FrameEncoder(self.take_frame, self.decode_frame, self.on_jpeg, p["image_rate_hz"],
                                    p["jpeg_quality"], p["image_scale"], self.on_frame_error)
        self.server = LiveViewServer(p["host"], p["port"], self.on_request, self.on_pages, p["call_timeout_s"] + 2.0,
                                     log=self.get_logger().info, state=self.on_state_request,
                                     on_refused=self.on_refused)
        try:
            self.server.start()
        except OSError as error:
            self.encoder.stop()
            raise StartupError(f"cannot serve on {p['host']}:{p['port']}: {error}") from None
        self.create_timer(1.0 / p["update_rate_hz"], self.on_update)
        self.create_timer(POLL_PERIOD_S, self.on_poll)
        self.create_timer(DEADLINE_CHECK_S, self.on_deadlines)

    def announce(self) -> None:
        """The start-up line (controller_manager_py.ros.node_main.run_node)."""
        self.get_logger().info(f"live view on {self.server.url} (robot manager {self.manager_name}, "
                               f"controller {self.controller_name})")

    # ---- pages and requests: from the web thread ----------------------------------------------
    def on_pages(self, count: int) -> None:
        self.pages = count
        self.wake.trigger()

    def on_request(self, request) -> concurrent.futures.Future:
        """A page's request (web thread): checked here, carried out on the executor's thread."""
        try:
            command = commands.parse(request, self.allowed + REFERENCE_PARAMS)
        except commands.CommandError as error:   # refused at once: counted, logged, the page told why
            self.on_refused("request", f"refused a page's request: {error}")
            raise
        answer: concurrent.futures.Future = concurrent.futures.Future()
        self.requests.put((command, answer))
        self.wake.trigger()
        return answer

    def on_refused(self, kind: str, why: str) -> None:
        """Bad input (web thread): counted, one line per kind every LOG_PERIOD_S at most."""
        self.refused_requests += 1
        self.throttle.warn(kind, f"{why} ({self.refused_requests} refused so far)")

    def on_state_request(self) -> concurrent.futures.Future:
        """GET /api/state (web thread): the newest state, built on the executor's thread."""
        answer: concurrent.futures.Future = concurrent.futures.Future()
        self.asked_s = time.monotonic()
        self.state_requests.put(answer)
        self.wake.trigger()
        return answer

    # ---- executor thread ---------------------------------------------------------------------
    def on_wake(self) -> None:
        while True:   # before watch(): each request's asked_s is then seen by it
            try:
                self.state_waiting.append(self.state_requests.get_nowait())
            except queue.Empty:
                break
        self.watch()
        if self.state_waiting and self.watched is not None:
            self.take()
        self.answer_state_requests()
        while True:
            try:
                command, answer = self.requests.get_nowait()
            except queue.Empty:
                return
            key = f"page {command.op} {command.name}"    # not the values: a line per kind of request
            if self.throttle.due(key):
                self.get_logger().info(f"page: {command.describe()}{self.throttle.suffix(key)}")
            self.carry_out(command, answer)

    def watch(self) -> None:
        """Subscribe to the high-rate topics while looked at (reader node, never spun): the ball, the
        reference and the arm while a page is connected or a script asked for /api/state less than
        API_FOLLOW_S ago, the camera while a page is connected. self.watched is replaced, not changed
        (the encoder thread reads it)."""
        page = self.pages > 0
        follow = page or time.monotonic() - self.asked_s < API_FOLLOW_S
        if follow and self.watched is None:
            self.watched = {
                "ball": self.reader.create_subscription(BallState, "/ball_state", lambda m: None, BALL_QOS),
                "reference": self.reader.create_subscription(PointStamped, "/ball_reference", lambda m: None,
                                                             QoSProfile(depth=KEPT)),
                "joints": self.reader.create_subscription(JointState, "/joint_states", lambda m: None,
                                                          QoSProfile(depth=1)),
            }
            self.following_since, self.ball_taken = time.monotonic(), False
            if not page:
                self.get_logger().info(f"asked for /api/state: following the ball and the arm until "
                                       f"{API_FOLLOW_S:g} s after the last request")
            self.on_poll()
        if page and "image" not in self.watched:
            image = self.reader.create_subscription(Image, self.params["image_topic"], lambda m: None,
                                                    QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT),
                                                    raw=True)
            self.watched = dict(self.watched, image=image)
            self.get_logger().info("a page is connected: following the ball, the arm and the camera")
            self.encoder.set_active(True)
        elif not page and self.watched is not None and "image" in self.watched:
            self.encoder.set_active(False)
            watched, self.watched = self.watched, {k: v for k, v in self.watched.items() if k != "image"}
            self.reader.destroy_subscription(watched["image"])
            if follow:
                self.get_logger().info("no page connected: following the ball and the arm for /api/state, "
                                       "not the camera")
        if not follow and self.watched is not None:
            watched, self.watched = self.watched, None
            for subscription in watched.values():
                self.reader.destroy_subscription(subscription)
            self.get_logger().info("no page connected and no /api/state request for a while: "
                                   "not following the high-rate topics")

    def carry_out(self, command: commands.Command, answer: concurrent.futures.Future) -> None:
        if command.op == "lifecycle":
            request = ChangeState.Request()
            request.transition.id, request.transition.label = command.transition_id, command.name
            self.call(self.change_state, request, command.describe(), answer,
                      lambda r: (r.success, "done" if r.success else "refused by the robot manager"))
        elif command.op == "trigger":
            self.call(self.triggers[command.name], Trigger.Request(), command.describe(), answer,
                      lambda r: (r.success, r.message or ("done" if r.success else "refused")))
        else:
            request = SetParameters.Request(parameters=[_parameter(k, v) for k, v in command.values.items()])

            def result(response):
                refused = [f"{p.name}: {r.reason or 'refused'}" for p, r in zip(request.parameters, response.results)
                           if not r.successful]
                self.poll_parameters()
                return (not refused, "; ".join(refused) or "done")
            self.call(self.set_params, request, command.describe(), answer, result)

    def call(self, client, request, what: str, answer: concurrent.futures.Future,
             result: Callable[[object], tuple]) -> None:
        """Call a service for the page; `answer` gets (ok, message) from the reply or the deadline."""
        if not client.service_is_ready():
            hint = " (is the robot manager running?)" if client.srv_name.startswith(self.manager_name) else ""
            answer.set_result((False, f"{what}: {client.srv_name} is not available{hint}"))
            return
        future = client.call_async(request)
        pending = _Pending(client, future, answer, what, time.monotonic() + self.params["call_timeout_s"])
        self.pending.append(pending)

        def done(f) -> None:
            if pending in self.pending:
                self.pending.remove(pending)
            if answer.done():
                return
            try:
                ok, message = result(f.result())
            except Exception as error:  # noqa: BLE001 - reported to the page
                ok, message = False, f"{type(error).__name__}: {error}"
            answer.set_result((ok, f"{what}: {message}"))
        future.add_done_callback(done)

    def on_deadlines(self) -> None:
        now = time.monotonic()
        for pending in [p for p in self.pending if p.deadline <= now]:
            self.pending.remove(pending)
            pending.client.remove_pending_request(pending.future)
            if not pending.answer.done():
                pending.answer.set_result((False, f"{pending.what}: {pending.client.srv_name} did not answer "
                                                  f"within {self.params['call_timeout_s']:g} s"))

    def on_poll(self) -> None:
        """While watched: the robot manager's lifecycle state and the controller's parameters."""
        self.model.manager.present = self.get_state.service_is_ready()
        self.model.controller["present"] = self.get_params.service_is_ready()
        if self.watched is None:
            return
        if self.model.manager.present and not self.polling["state"]:
            self.polling["state"] = True
            self.call(self.get_state, GetState.Request(), "get state", self._polled("state"),
                      self._on_state)
        self.poll_parameters()

    def poll_parameters(self) -> None:
        if self.model.controller["present"] and not self.polling["params"]:
            self.polling["params"] = True
            names = list(self.gain_names + REFERENCE_PARAMS)
            self.call(self.get_params, GetParameters.Request(names=names), "get parameters",
                      self._polled("params"), lambda r: self._on_parameters(names, r))

    def _polled(self, what: str) -> concurrent.futures.Future:
        answer: concurrent.futures.Future = concurrent.futures.Future()
        answer.add_done_callback(lambda f: self.polling.__setitem__(what, False))
        return answer

    def _on_state(self, response) -> tuple:
        self.model.manager.lifecycle_state = response.current_state.label
        return True, ""

    def _on_parameters(self, names, response) -> tuple:
        self.model.controller["parameters"] = {n: _value(v) for n, v in zip(names, response.values)}
        return True, ""

    def on_estop(self, msg: Bool) -> None:
        self.model.manager.emergency_stop_active = bool(msg.data)

    def on_event(self, msg: DiagnosticStatus) -> None:
        self.model.on_manager_event(msg.level[0] if isinstance(msg.level, bytes) else msg.level, msg.message,
                                    {kv.key: kv.value for kv in msg.values}, time.time())

    def on_transition(self, msg: TransitionEvent) -> None:
        self.model.manager.lifecycle_state = msg.goal_state.label

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        name = f"{self.params['controller_node'].strip('/')}: Plant Estimate"
        for status in msg.status:
            if status.name == name:
                self.model.controller["plant"] = status.message

    def on_update(self) -> None:
        """Take what the watched topics hold, update the model, push one state to the pages (if any)
        and answer the /api/state requests that wait for a first ball state."""
        self.watch()
        if self.watched is None:
            return
        self.take()
        self.answer_state_requests()
        if self.pages > 0:
            self.server.push_state(self.snapshot())

    def take(self) -> None:
        """The watched topics' waiting messages into the model."""
        now = time.monotonic()
        for msg in _take(self.watched["reference"]):
            self.model.on_reference(msg.point.x, msg.point.y, _stamp_s(msg.header))
        for msg in _take(self.watched["ball"]):
            ball = Ball(msg.x, msg.y, msg.vx, msg.vy, msg.tracking_valid, msg.ball_found, msg.markers_found,
                        msg.pixel_u, msg.pixel_v)
            if self.model.on_ball(ball, _stamp_s(msg.header)):
                self.wall["ball"] = now
            self.ball_taken = True
        for msg in _take(self.watched["joints"]):
            self.model.on_joint_velocities(msg.velocity, _stamp_s(msg.header))
            self.wall["joints"] = now

    def answer_state_requests(self) -> None:
        """Answer the waiting /api/state requests with the state the model holds (the caller has
        taken the newest messages); just after the ball state was subscribed, once its first
        message is there or FIRST_STATE_WAIT_S has passed."""
        if not self.state_waiting:
            return
        if (self.watched is not None and not self.ball_taken
                and time.monotonic() - self.following_since < FIRST_STATE_WAIT_S):
            return
        snapshot = self.snapshot()
        waiting, self.state_waiting = self.state_waiting, []
        for answer in waiting:
            if not answer.done():
                answer.set_result(snapshot)

    def snapshot(self) -> dict:
        """The state the pages and /api/state get: a new dict, never changed once handed over."""
        now = time.monotonic()
        snapshot = self.model.snapshot()
        snapshot["fresh"] = {k: now - t < FRESH_S for k, t in self.wall.items()}
        snapshot["gain_names"] = list(self.gain_names)
        snapshot["pending_calls"] = len(self.pending)
        snapshot["refused_requests"] = self.refused_requests
        return snapshot

    # ---- the encoder thread ------------------------------------------------------------------
    def take_frame(self) -> Optional[bytes]:
        image = (self.watched or {}).get("image")
        if image is None:
            return None
        frames = _take(image, 2)
        return frames[-1] if frames else None

    def decode_frame(self, serialized: bytes):
        image, why = decode_image(image_from_cdr(serialized))
        if image is None:
            self.on_frame_error(why)
        return image

    def on_jpeg(self, jpeg: bytes, width: int, height: int) -> None:
        self.model.frames_sent += 1
        self.model.image.update(width=width, height=height)
        self.server.push_frame(jpeg)

    def on_frame_error(self, why: str) -> None:
        self.get_logger().warning(f"camera frame not shown: {why}", throttle_duration_sec=10.0)

    def destroy_node(self) -> None:
        self.encoder.stop()
        self.server.stop()
        self.reader.destroy_node()
        super().destroy_node()


main = main_for(LiveViewNode)
