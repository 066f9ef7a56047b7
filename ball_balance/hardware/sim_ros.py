"""The simulated arm's ROS side: publishers, services and disturbance topics on the manager's node.

Used by MujocoSystem (ball_balance/hardware/mujoco_system.py); built once in on_configure.
Publishing is called from the real-time loop (truth, clock, detections: small messages at
their own rates) and from the camera thread (images; with camera_process=true the camera's
child process publishes them, ball_balance/hardware/camera_process.py). Services and disturbance topics
(executor thread) hand requests to the system (`controls`), whose loop applies them.
"""
from __future__ import annotations

import math
import sys
import time
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from typing import Mapping

import numpy as np
from ball_tracker_msgs.msg import BallState
from ball_tracker_msgs.srv import SetBallForce
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Vector3Stamped, WrenchStamped
from rcl_interfaces.srv import GetParameters
from rclpy.clock import Clock as RosClock
from rclpy.clock import ClockType
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Bool, Header
from std_srvs.srv import SetBool, Trigger

from ball_balance.plate_geometry import PLATE_FRAME
from ball_balance.robot import BASE_FRAME
from ball_balance.ros.images import encode_image
from ball_balance.sim.config import camera_intrinsics
from ball_balance.sim.lockstep import REPORT_PERIOD_S, PaceReport
from ball_balance.tf.ros import StaticTransformBroadcaster, stamp_to_ns, transform_to_msg
from ball_balance.tf.transform import Transform
from controller_manager_py.manager.throttle import Throttle
from controller_manager_py.parameters import ParameterError

# Images: sensor-data QoS (docs/design.md section 4), keep-last 1 (a best-effort frame is never resent, older
# ones are of no use); whole frames at full rate need config/dds (docs/transport.md).
# image_reliable=true: reliable keep-last 2 (also serves best-effort subscribers).
IMAGE_SENSOR_DATA = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT, durability=DurabilityPolicy.VOLATILE)
IMAGE_RELIABLE = QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
PARTICIPANT_PREFIX_BYTES = 12   # an RTPS GUID: participant prefix (12 bytes), then the entity id
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)
# how long a service waits for the control loop to take its request (one cycle, normally)
REQUEST_WAIT_S = 5.0
FORCE_CHANGES = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                           reliability=ReliabilityPolicy.RELIABLE)
# The largest /sim/push_ball accepted (m/s): the fastest push a domain may be given (SimConfig
# push_speed_m_s <= 2.0); the evaluation domains push at 0.15-0.3 m/s, and at 2 m/s the ball
# crosses the 0.457 m plate in a quarter of a second. A larger push only throws the ball away.
MAX_PUSH_M_S = 2.0


def camera_info_msg(camera, frame_id: str) -> CameraInfo:
    """The camera's CameraInfo (pinhole, no distortion) for a CameraConfig."""
    fx, fy, cx, cy = camera_intrinsics(camera)
    info = CameraInfo(width=camera.width_px, height=camera.height_px, distortion_model="plumb_bob")
    info.header.frame_id = frame_id
    info.d = [0.0] * 5
    info.k = [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]
    info.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    info.p = [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]
    return info


def _taken(request: Future):
    """The result of a request to the control loop, None if the loop has not taken it within
    REQUEST_WAIT_S (it still will: the request stays queued)."""
    try:
        return request.result(timeout=REQUEST_WAIT_S)
    except FutureTimeout:
        return None


def _since(request: Future) -> str:
    """When a request to the control loop took effect, in words (once it has, or in time)."""
    taken_s = _taken(request)
    if taken_s is None:
        return f"from the control loop's next cycle (none ran within {REQUEST_WAIT_S:g} s)"
    return f"from t={taken_s:.6f} s"


def stamp(time_s: float) -> Time:
    sec = int(time_s // 1)
    return Time(sec=sec, nanosec=min(999_999_999, int(round((time_s - sec) * 1e9))))


class SimRosIo:
    def __init__(self, node, world, params: Mapping[str, object], controls):
        self.node, self.world, self.params = node, world, params
        self.logger = node.get_logger()
        image_qos = IMAGE_RELIABLE if params["image_reliable"] else IMAGE_SENSOR_DATA
        # camera_process=true: the camera's child process publishes the images itself
        in_thread = params["camera_enabled"] and not params["camera_process"]
        self.image_pub = node.create_publisher(Image, "/camera/image_raw", image_qos) if in_thread else None
        self.info_pub = node.create_publisher(CameraInfo, "/camera/camera_info", image_qos) if in_thread else None
        self.truth_pub = node.create_publisher(BallState, "/sim/ball_truth", qos_profile_sensor_data)
        self.dropped_pub = node.create_publisher(Bool, "/sim/ball_dropped", LATCHED)
        self.pushed_pub = node.create_publisher(Vector3Stamped, "/sim/ball_pushed", QoSProfile(depth=10))
        # transient local, the last changes kept: a monitor that starts later still learns
        # the force held from the start
        self.force_pub = node.create_publisher(Vector3Stamped, "/sim/ball_force", FORCE_CHANGES)
        self.clock_pub = node.create_publisher(Clock, "/clock", QoSProfile(depth=1))
        self.detection_pub = (node.create_publisher(BallState, "/ball_state", qos_profile_sensor_data)
                              if params["truth_fed"] else None)
        # latency_trace: (event, sim time) as Header(frame_id=event, stamp); the DDS sample's
        # source timestamp is the wall-clock time of the event
        self.trace_pub = (node.create_publisher(Header, "/sim/latency_trace", QoSProfile(depth=100))
                          if params["latency_trace"] else None)
        self.controls = controls
        self._closed = False
        self._triggers = {}          # lock-step: /plate_cmd publisher node -> its control_trigger ("" if none)
        self._trigger_clients = {}
        self._commands_seen = False
        self._pace = None            # lock-step's pace report (follow_answers)
        self.refused_force_requests = 0   # /sim/set_ball_force requests refused
        self.refused_disturbances = 0     # /sim/push_ball and /sim/ball_wrench messages refused
        self.throttle = Throttle(self.logger)
        # a /sim/ball_wrench acts for wrench_duration (one physics step at least): its force may
        # change the ball's speed by MAX_PUSH_M_S at most, as a push; its torque, that force's at
        # the ball's rim
        acts_s = max(params["wrench_duration"], world.physics_dt_s)
        self.max_wrench_force_n = world.knobs.ball_mass_kg * MAX_PUSH_M_S / acts_s
        self.max_wrench_torque_n_m = self.max_wrench_force_n * world.config.ball_radius_m
        # stamps = sim time + this offset: 0 with sim_time (the component owns /clock), else
        # the wall-clock time at start, so stamps compare with wall-clock nodes
        self.stamp_offset_s = 0.0
        self.services = [
            node.create_service(Trigger, "/sim/reset_ball", self._handle_reset),
            node.create_service(Trigger, "/sim/reset_world", self._handle_reset_world),
            node.create_service(SetBool, "/sim/set_pause", self._handle_pause),
            node.create_service(Trigger, "/sim/step_simulation", self._handle_step),
            node.create_service(SetBallForce, "/sim/set_ball_force", self._handle_ball_force),
            node.create_service(Trigger, "/sim/inject_hardware_error", self._handle_hardware_error),
        ]
        self.timers = []   # lock-step's (follow_answers)
        self.subscriptions = [
            node.create_subscription(WrenchStamped, "/sim/ball_wrench", self._on_wrench, 10),
            node.create_subscription(Vector3Stamped, "/sim/push_ball", self._on_push, 10),
        ]
        self.paused = params["start_paused"]
        self._dropped = None
        self._camera_info = camera_info_msg(self.world.config.camera, self.params["camera_frame_id"])
        self.static_tf = StaticTransformBroadcaster(node)
        self.static_tf.send_transform(self._camera_transform())
        self._clock = Clock()
        self.update_dropped(False, None)

    def _camera_transform(self):
        """base_link -> camera frame (optical convention: z forward, x right, y down in the image)."""
        c_W, R_WC = self.world.camera_pose()  # MuJoCo camera axes: x right, y up, looking along -z
        R_W_optical = R_WC @ np.diag([1.0, -1.0, -1.0])
        transform = Transform.from_values(tuple(c_W), tuple(Rotation.from_matrix(R_W_optical).as_quat()))
        return transform_to_msg(transform, BASE_FRAME, self.params["camera_frame_id"], None)

    def _publish(self, publisher, msg) -> None:
        """Publish; after close() or the context's shutdown (Ctrl-C, SIGTERM) quietly do nothing."""
        try:
            publisher.publish(msg)
        except Exception:  # noqa: BLE001 - rclpy raises RCLError/InvalidHandle types at shutdown
            if self.node.context.ok() and not self._closed:
                raise

    def trace(self, event: str, time_s: float) -> None:
        """latency_trace: "capture" (frame snapshot taken, loop), "rendered" (camera thread),
        "command" (a new joint target written, loop); stamp = the frame's or the write's time."""
        if self.trace_pub is not None:
            self._publish(self.trace_pub, Header(stamp=stamp(time_s + self.stamp_offset_s), frame_id=event))

    # ---- camera thread ------------------------------------------------------------------
    def publish_image(self, image_bgr, time_s: float) -> None:
        msg = encode_image(image_bgr, stamp(time_s + self.stamp_offset_s), self.params["camera_frame_id"])
        self._camera_info.header.stamp = msg.header.stamp
        self._publish(self.image_pub, msg)
        self._publish(self.info_pub, self._camera_info)

    # ---- real-time loop -----------------------------------------------------------------
    def publish_truth(self, truth) -> None:
        """The true ball state; pixel_u/v: the ball centre projected into the camera image."""
        frame = self.world.frame_truth(truth)
        msg = BallState(x=truth.x, y=truth.y, vx=truth.vx, vy=truth.vy, ball_found=not truth.dropped,
                        tracking_valid=not truth.dropped, markers_found=4,
                        pixel_u=frame.pixel_u, pixel_v=frame.pixel_v)
        msg.header.stamp = stamp(truth.time_s + self.stamp_offset_s)
        msg.header.frame_id = PLATE_FRAME
        self._publish(self.truth_pub, msg)

    def publish_detection(self, time_s: float, x: float, y: float) -> None:
        """truth_fed mode: a tracker-like BallState from the (noisy) truth; no Kalman velocity."""
        truth = self.world.ball_truth()
        msg = BallState(x=x, y=y, vx=truth.vx, vy=truth.vy, ball_found=not truth.dropped,
                        tracking_valid=not truth.dropped, markers_found=4)
        msg.header.stamp = stamp(time_s + self.stamp_offset_s)
        msg.header.frame_id = PLATE_FRAME
        self._publish(self.detection_pub, msg)

    def publish_pushed(self, time_s: float, dvx_m_s: float, dvy_m_s: float) -> None:
        """A push applied (the domain's, or one asked for on /sim/push_ball): its velocity change
        in plate axes, stamped with the simulated time it acted, so that monitors can time the
        recovery."""
        msg = Vector3Stamped()
        msg.header.stamp = stamp(time_s + self.stamp_offset_s)
        msg.header.frame_id = PLATE_FRAME
        msg.vector.x, msg.vector.y = dvx_m_s, dvy_m_s
        self._publish(self.pushed_pub, msg)

    def publish_force(self, time_s: float, fx_n: float, fy_n: float) -> None:
        """The constant force on the ball now in effect (the held one and the domain's force
        steps; N, plate axes) at each change, stamped with the simulated time it began, so that
        monitors can time the recovery from each step."""
        msg = Vector3Stamped()
        msg.header.stamp = stamp(time_s + self.stamp_offset_s)
        msg.header.frame_id = PLATE_FRAME
        msg.vector.x, msg.vector.y = fx_n, fy_n
        self._publish(self.force_pub, msg)

    def publish_clock(self, time_s: float) -> None:
        self._clock.clock = stamp(time_s)
        self._publish(self.clock_pub, self._clock)

    def update_dropped(self, dropped: bool, truth) -> None:
        if dropped == self._dropped:
            return
        self._dropped = dropped
        self._publish(self.dropped_pub, Bool(data=dropped))
        if dropped:
            self.logger.warning(f"ball dropped off the plate at t={truth.time_s:.3f} s "
                                f"(x={truth.x:+.3f} m, y={truth.y:+.3f} m); call /sim/reset_ball to put it back")

    # ---- executor thread ----------------------------------------------------------------
    def follow_answers(self, answers, camera) -> None:
        """Lock-step: feed `answers` (a FrameAnswerGate) the /ball_state stamps and the /plate_cmd
        arrivals, and say every REPORT_PERIOD_S how fast simulated time runs and why."""
        self._answers = answers
        self.subscriptions += [
            self.node.create_subscription(BallState, "/ball_state", lambda msg: answers.on_state(
                stamp_to_ns(msg.header.stamp) * 1e-9 - self.stamp_offset_s), qos_profile_sensor_data),
            self.node.create_subscription(Vector3Stamped, "/plate_cmd", self._on_command, 10),
        ]
        self._pace = PaceReport(answers, camera, self.world, 1.0 / self.params["camera_rate_hz"])
        steady = RosClock(clock_type=ClockType.STEADY_TIME)
        self.timers = [self.node.create_timer(REPORT_PERIOD_S, self._report_pace, clock=steady),
                       self.node.create_timer(1.0, self._check_hosted_controller, clock=steady)]

    def _on_command(self, msg) -> None:
        if not self._commands_seen:    # the first command: what answers a frame, before waiting on it
            self._commands_seen = True
            self._check_hosted_controller()
        self._answers.on_command()

    def _check_hosted_controller(self) -> None:
        """Whether a /plate_cmd answers a state at once, or the state's arrival must count as
        the answer (FrameAnswerGate.answer_on_state): a controller hosted in the manager (on a
        node of its own, like every ros2_control controller) steps on the manager's time grid,
        and a controller node stepping on its own timer (`control_trigger` 'timer', the policy
        node) steps at its next tick of simulated time, which the waiting simulation would
        never reach. The nodes of one process share its DDS participant, whose GUID prefix
        begins every endpoint's GID; a node's trigger is asked once through its parameter
        service, and until it answers the node counts as stepping on a timer (the simulation
        then never waits for a command that cannot come)."""
        name, namespace = self.node.get_name(), self.node.get_namespace()
        ours = {bytes(info.endpoint_gid[:PARTICIPANT_PREFIX_BYTES])
                for info in self.node.get_publishers_info_by_topic("/sim/ball_truth")
                if info.node_name == name and info.node_namespace == namespace}
        publishers = [(bytes(info.endpoint_gid[:PARTICIPANT_PREFIX_BYTES]) in ours,
                       info.node_namespace.rstrip("/") + "/" + info.node_name)
                      for info in self.node.get_publishers_info_by_topic("/plate_cmd")]
        hosted = any(in_process for in_process, _ in publishers)
        nodes = {node for in_process, node in publishers if not in_process}
        for node in nodes - set(self._triggers):
            self._ask_trigger(node)
        self._answers.answer_on_state = hosted or any(self._triggers.get(node, "timer") == "timer"
                                                      for node in nodes)

    def _ask_trigger(self, node: str) -> None:
        """Ask `node` for its control_trigger (an empty answer for a node without one)."""
        client = self._trigger_clients.get(node)
        if client is None:
            client = self._trigger_clients[node] = self.node.create_client(GetParameters, f"{node}/get_parameters")
        if not client.service_is_ready():
            return
        future = client.call_async(GetParameters.Request(names=["control_trigger"]))

        def take(done) -> None:
            values = done.result().values if done.result() is not None else []
            self._triggers[node] = values[0].string_value if values else ""
        future.add_done_callback(take)

    def _report_pace(self) -> None:
        line = self._pace.line(time.monotonic())
        if line:
            self.logger.info(line)

    # The replies below come once the loop has applied the request (services run on the
    # executor's thread, the loop on its own), so what a caller reads next follows it.
    def _handle_reset(self, request, response):
        since = _since(self.controls.request_reset_ball())
        response.success, response.message = True, f"ball at rest at the plate centre {since}"
        return response

    def _handle_hardware_error(self, request, response):
        self.controls.request_hardware_error()
        response.success = True
        response.message = "the next read() fails, as a driver's does when it loses the robot"
        return response

    def _handle_reset_world(self, request, response):
        since = _since(self.controls.request_reset_world())
        response.success = True
        response.message = (f"arm at home, ball at rest at ({self.params['ball_x']:+.3f}, "
                            f"{self.params['ball_y']:+.3f}) m {since}; the clock keeps running")
        return response

    def _handle_pause(self, request, response):
        self.paused = bool(request.data)
        since = _since(self.controls.request_pause(self.paused))
        response.success = True
        response.message = f"simulation {'paused' if self.paused else 'running'} {since}"
        return response

    def _handle_step(self, request, response):
        steps = self.params["step_simulation_steps"]
        if not self.paused:
            response.success, response.message = False, "not paused: call /sim/set_pause with data: true first"
            return response
        taken = self.controls.request_steps(steps)
        span = _taken(taken)
        of_steps = f"{steps} physics step(s) of {self.world.physics_dt_s * 1e3:g} ms"
        if span is not None:
            response.success, response.message = True, f"advanced {of_steps}: t={span[0]:.6f} -> {span[1]:.6f} s"
        elif taken.done():
            response.success, response.message = False, f"{of_steps} not taken: the simulation was resumed first"
        else:
            response.success = True
            response.message = (f"{of_steps} requested; the control loop takes them at its next cycle (none "
                                f"ran within {REQUEST_WAIT_S:g} s)")
        return response

    def _handle_ball_force(self, request, response):
        try:
            taken = self.controls.request_ball_force(request.ball_force_deg, request.ball_force_dir_deg)
        except ParameterError as error:
            self.refused_force_requests += 1
            response.success, response.message = False, f"refused, the force in effect is unchanged: {error}"
            self.logger.warning(f"/sim/set_ball_force: {response.message} ({self.refused_force_requests} refused "
                                "so far)", throttle_duration_sec=1.0)
            return response
        held = self.controls.ball_force_words(request.ball_force_deg, request.ball_force_dir_deg)
        response.success, response.message = True, f"{held} {_since(taken)}"
        self.logger.info(f"/sim/set_ball_force: {response.message}")
        return response

    def _refuse(self, topic: str, why: str) -> None:
        """A disturbance message refused: counted, and said at most every few seconds per topic."""
        self.refused_disturbances += 1
        self.throttle.warn(topic, f"{topic}: {why}; ignored ({self.refused_disturbances} refused so far)")

    def _plate_axes(self, frame_id: str, what: str):
        """True for the plate's axes, False for the world's; None (refused) for another frame."""
        if frame_id in ("", PLATE_FRAME):
            return True
        if frame_id in (BASE_FRAME, "world"):
            return False
        self._refuse(what, f"frame_id '{frame_id}' not supported (use '{PLATE_FRAME}' or '{BASE_FRAME}')")
        return None

    def _on_wrench(self, msg: WrenchStamped) -> None:
        f, t = msg.wrench.force, msg.wrench.torque
        values = (f.x, f.y, f.z, t.x, t.y, t.z)
        if not all(math.isfinite(v) for v in values):
            self._refuse("/sim/ball_wrench", f"non-finite wrench {values}")
            return
        if math.hypot(*values[:3]) > self.max_wrench_force_n or math.hypot(*values[3:]) > self.max_wrench_torque_n_m:
            self._refuse("/sim/ball_wrench", f"wrench {values} beyond {self.max_wrench_force_n:.3g} N, "
                         f"{self.max_wrench_torque_n_m:.3g} N m (a push of {MAX_PUSH_M_S:g} m/s at most)")
            return
        axes = self._plate_axes(msg.header.frame_id, "/sim/ball_wrench")
        if axes is not None:
            self.controls.request_wrench(values[:3], values[3:], self.params["wrench_duration"], axes)

    def _on_push(self, msg: Vector3Stamped) -> None:
        v = msg.vector
        values = (v.x, v.y, v.z)
        if not all(math.isfinite(x) for x in values):
            self._refuse("/sim/push_ball", f"non-finite velocity {values}")
            return
        if math.hypot(*values) > MAX_PUSH_M_S:
            self._refuse("/sim/push_ball", f"velocity {values} faster than {MAX_PUSH_M_S:g} m/s")
            return
        axes = self._plate_axes(msg.header.frame_id, "/sim/push_ball")
        if axes is not None:
            self.controls.request_push(values, axes)

    def _log_at_close(self, text: str) -> None:
        """Log a line while closing. close() usually runs once Ctrl-C or SIGTERM has shut the
        context down (the manager's destroy_node shuts the hardware down then); the ROS logger
        could no longer publish to /rosout (rcl would print an error instead), so the line goes
        to stderr in the logger's format."""
        if self.node.context.ok():
            self.logger.info(text)
        else:
            print(f"[INFO] [{self.logger.name}]: {text}", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self._pace is not None and not self._closed:
            self._log_at_close(self._pace.summary())
        self._closed = True
        for entity in (self.image_pub, self.info_pub, self.truth_pub, self.dropped_pub, self.pushed_pub, self.force_pub,
                       self.clock_pub, self.detection_pub, self.trace_pub):
            if entity is not None:
                self.node.destroy_publisher(entity)
        for timer in self.timers:
            self.node.destroy_timer(timer)
        for service in self.services:
            self.node.destroy_service(service)
        for subscription in self.subscriptions:
            self.node.destroy_subscription(subscription)
        for client in self._trigger_clients.values():
            self.node.destroy_client(client)
