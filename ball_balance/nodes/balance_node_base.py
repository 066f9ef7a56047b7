"""What the balance controller nodes share: inputs checked per message, one control step per
new ball state, a watchdog timer, dead-peer detection, safety logging, run-time parameter
changes and the common outputs. Subclasses set SCHEMA, CONTROLLER and `publish_joints()`
(forward position commands vs a single-point trajectory); `make_pipeline()` may be overridden.

Inputs
  /ball_state    ball_tracker_msgs/BallState (sensor-data QoS, newest only): the ball, plate frame.
  /plate_pose    geometry_msgs/PoseWithCovarianceStamped (optional): the tracker's plate pose fit,
                 stamp equal to the matching /ball_state; its covariance gives the state's
                 position_std_m (vision/pose_quality.py), which decides whether a frame with
                 hidden markers is good enough. Without a /plate_pose publisher (a tracker that
                 does not publish it) the min_markers rule decides.
  /ball_level_offset geometry_msgs/Vector3Stamped (optional; a tracker with
                 disturbance_time_constant_s > 0): its filter's constant disturbance as a
                 plate-level offset [rad], which the controllers cancel in place of their own
                 estimate's; one within LEVEL_OFFSET_MAX_AGE_S of the ball state is used.
  /joint_states  sensor_msgs/JointState (newest only): the arm's current joint positions.
Outputs
  /plate_cmd      geometry_msgs/Vector3Stamped, frame plate_center: x = u_x, y = u_y [rad]
                  (z = 0), for the tracker's Kalman feed-forward: the commanded tilt less the
                  estimated disturbance's level offset (the tilt as the ball feels it), or as
                  commanded when the tracker estimates the disturbance itself
                  (control/pipeline.py TickResult.plate_cmd).
  /ball_reference geometry_msgs/PointStamped, frame plate_center: the target at the message's
                  stamp (z = 0; the control itself aims at it a latency ahead) while engaged;
                  not published otherwise.
  ~/statistics/{full,names,values} (pal_statistics_msgs, every 0.1 s): the plant estimate,
                  `disturbance_tilt_x_deg`, `disturbance_tilt_y_deg` (the disturbance d as a
                  plate-level offset: the tilt at which the ball stays still, asin(d / (k g)),
                  control/estimation.py `level_offset_deg`; a plate mounted 2 degrees off level
                  shows as 2 degrees) and `plant_gain_ratio` (estimated k g / configured).
  /diagnostics    diagnostic_msgs/DiagnosticArray (every second, steady clock): status
                  "<node>: Plant Estimate" (level OK), the same three values and, as its
                  message, the level offset in words (control/estimation.py
                  `level_offset_summary`), so a user learns that the plate is not level.

Every /ball_state is judged on arrival (control/plausibility.py) and only a plausible one
from the publisher the node locked onto replaces the state in use: stamps in the future or
older than max_prediction_s, balls off the plate or too fast, positions inconsistent with the
recent motion, and messages from a second publisher on /ball_state are refused, counted and
logged (throttled; a second publisher is named from the ROS graph). A bad message therefore
never displaces a good one, and the safety supervisor sees only the good state ageing.

Control steps: control_trigger "ball_state" (default) steps once per accepted new state, at
once (no wait for a tick), and the control_rate_hz timer becomes the watchdog that steps only
when no state has come for 1.5 state intervals, so holding, returning home and homing go on
when states stop. The pipeline's PID, MPC model, shaper and delay estimate assume
1/control_rate_hz per step, so control_rate_hz must equal the camera rate. "timer" steps every
control_rate_hz tick on the newest accepted state (a fresh state waits up to one period).
Measured choice (rates matched, two busy processes): docs/control.md, "When it steps". The
subscriptions keep only the newest message: a node that falls behind drops old states
instead of working through a queue of them.

Dead peers: no /joint_states for joint_states_timeout_s, or under use_sim_time no /clock
progress for as long, stops all commands (the arm holds where it is, the node says why); when they return
the pipeline restarts from homing at the measured joints. A clock that jumps back (a
simulation reset) restarts it too. The peer watchdog runs on the steady clock.

Plate pose: forward kinematics of /joint_states through the robot description (the same
file robot_state_publisher serves on /tf), not a TF lookup: it has no TF latency, cannot
be missing once joint states arrive, and is exactly what robot_state_publisher would
publish for base_link -> plate_center. Until the first /joint_states nothing is commanded
(so the first command can never jump); a joint_states message lacking one of our joints is
ignored with a throttled warning.
"""
from __future__ import annotations

import math
import time
from collections import Counter, OrderedDict
from typing import Optional

import numpy as np
from ball_tracker_msgs.msg import BallState
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped, Vector3Stamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import JointState

from ball_balance.control import config as control_config
from ball_balance.control.estimation import level_offset_summary, plant_statistics
from ball_balance.control.kinematics import Chain, KinematicsError
from ball_balance.control.pipeline import ControlPipeline
from ball_balance.control.plausibility import BallStateGate, Heartbeat, SourceLock, gate_config
from ball_balance.control.references import ReferenceError
from ball_balance.control.safety import LEVEL_OFFSET_MAX_AGE_S, LEVEL_OFFSET_TOPIC, BallObservation, Mode
from ball_balance.plate_geometry import PLATE_FRAME, PLATE_SIDE_M
from ball_balance.robot import JOINT_NAMES, RobotDescriptionError, robot_description_path
from ball_balance.vision.pose_quality import ball_position_std_m
from controller_manager_py.parameters import Param, ParameterError, declare_parameters
from controller_manager_py.realtime import set_process_realtime_priority
from controller_manager_py.ros.node_main import StartupError
from controller_manager_py.ros.statistics_publisher import StatisticsRegistry

NEWEST_ONLY_SENSOR = QoSProfile(depth=1, reliability=qos_profile_sensor_data.reliability,
                                durability=qos_profile_sensor_data.durability)
NEWEST_ONLY = QoSProfile(depth=1)
BALL_TOPIC = "/ball_state"
PLATE_POSE_TOPIC = "/plate_pose"
WATCHDOG_PERIOD_S = 0.1        # steady-clock checks of the peers
GRAPH_CHECK_PERIOD_S = 1.0     # publishers on /ball_state and /plate_pose
UNNAMED = "(a node not yet named in the graph)"
STATS_PERIOD_S = 10.0          # how often the step statistics are logged
DIAGNOSTICS_PERIOD_S = 1.0     # /diagnostics, as the controller manager's
# parameters of the node itself, beside its controller's SCHEMA
NODE_SCHEMA = [
    # above the tracker (40) and the simulated camera (30): the newest frame's state is
    # finished before the next frame is worked on
    Param("thread_priority", 45, "SCHED_FIFO priority (1-99) of every thread of the node (its DDS receive "
          "threads, the executor): a new ball state is taken and acted on at once on a busy machine; 0: normal "
          "scheduling. Needs CAP_SYS_NICE or an rtprio limit (else one warning, normal scheduling)", "", 0, 99,
          read_only=True),
]


def _stamp_ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class BalanceControllerNode(Node):
    SCHEMA: list = []
    CONTROLLER = "pid"

    def __init__(self, name: str):
        super().__init__(name)
        self.params = dict(declare_parameters(self, [*self.SCHEMA, *NODE_SCHEMA]))
        self._schema = {p.name: p for p in self.SCHEMA}
        try:
            urdf = robot_description_path().read_text()
            chain = Chain.from_urdf(urdf, JOINT_NAMES)
            self.kinematics = control_config.plate_kinematics(chain, self.params)
            control_config.reference(self.params)
        except (RobotDescriptionError, KinematicsError, ReferenceError, OSError) as error:
            raise StartupError(str(error)) from None
        self.pipeline = self.make_pipeline()
        self.gate = BallStateGate(gate_config(self.params, PLATE_SIDE_M / 2.0, control_config.k_g(self.params)))
        self.source = SourceLock()
        self._period_s = 1.0 / self.params["control_rate_hz"]
        self._event_driven = self.params["control_trigger"] == "ball_state"
        self._ball: Optional[BallState] = None        # the state in use (accepted)
        self._ball_std_m = 0.0                        # its position_std_m (0.0 = unknown)
        self._waiting_for_pose: Optional[BallState] = None  # accepted, its /plate_pose not yet here
        self._waiting_since_s = 0.0
        self._pose_std: OrderedDict[int, float] = OrderedDict()   # /plate_pose stamp (ns) -> std
        self._q: Optional[np.ndarray] = None
        self._mode: Optional[Mode] = None
        self._last_state_step_s = -math.inf           # steady time of the last step on a new state
        self._last_stop_note_s = 0.0
        self._state_interval_s = self._period_s       # running estimate of the /ball_state interval
        self._last_state_s: Optional[float] = None
        self._last_now_ns: Optional[int] = None
        self.refusals: Counter = Counter()            # refused /ball_state messages by kind
        self.dropped_ball_states = 0                  # all refused /ball_state messages
        self.ticks = 0
        self._steps = Counter()                       # control steps by trigger, since the last report
        self._arrival_ages_s: list = []               # age of accepted states on arrival
        self._next_report_s = time.monotonic() + STATS_PERIOD_S
        self.stopped_reason = ""                      # non-empty: commands stopped (a dead peer)
        timeout = self.params["joint_states_timeout_s"]
        self.joint_beat, self.clock_beat = Heartbeat(timeout), Heartbeat(timeout)
        self._sim_time = bool(self.get_parameter("use_sim_time").value)
        self._clock_seen_ns: Optional[int] = None
        self._publishers: list = []                   # "node" names on /ball_state
        self._locked_name = ""
        self._plate_pose_published = False
        self._next_graph_check_s = 0.0

        self.create_subscription(BallState, BALL_TOPIC, self.on_ball_state, NEWEST_ONLY_SENSOR)
        self.create_subscription(PoseWithCovarianceStamped, PLATE_POSE_TOPIC, self.on_plate_pose,
                                 qos_profile_sensor_data)
        self._level: Optional[tuple] = None          # (stamp ns, (u_x, u_y)) of the last /ball_level_offset
        self.create_subscription(Vector3Stamped, LEVEL_OFFSET_TOPIC, self.on_level_offset, qos_profile_sensor_data)
        self.create_subscription(JointState, "/joint_states", self.on_joint_states, NEWEST_ONLY)
        self.plate_cmd_pub = self.create_publisher(Vector3Stamped, "/plate_cmd", 10)
        self.reference_pub = self.create_publisher(PointStamped, "/ball_reference", 10)
        self.statistics = StatisticsRegistry(self, "~/statistics")
        self._plant_entries = plant_statistics(lambda: self.pipeline.plant)
        self.statistics.set_entries(self._plant_entries)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.add_on_set_parameters_callback(self.on_set_parameters)
        self.timer = self.create_timer(self._period_s, self.on_tick)
        steady_clock = Clock(clock_type=ClockType.STEADY_TIME)
        self.watchdog = self.create_timer(WATCHDOG_PERIOD_S, self.on_watchdog, clock=steady_clock)
        self.create_timer(DIAGNOSTICS_PERIOD_S, self.on_diagnostics, clock=steady_clock)
        # last, once the node's threads exist (threads started later inherit the policy)
        priority = self.params["thread_priority"]
        if priority > 0 and not set_process_realtime_priority(priority):
            self.get_logger().warning(f"could not give the node's threads SCHED_FIFO priority {priority} (needs "
                                      "CAP_SYS_NICE or an rtprio limit); running at normal priority")

    def announce(self) -> None:
        """The start-up line (controller_manager_py.ros.node_main.run_node)."""
        trigger = "each new ball state" if self._event_driven else f"{self.params['control_rate_hz']:.0f} Hz"
        self.get_logger().info(
            f"{self.CONTROLLER.upper()} balance controller, a step per {trigger} (watchdog "
            f"{self.params['control_rate_hz']:.0f} Hz), reference {self.params['reference_kind']}; "
            "waiting for /joint_states and /ball_state")

    def make_pipeline(self) -> ControlPipeline:
        """A fresh pipeline (start-up, and after a dead peer returned) at the current parameters."""
        return ControlPipeline(control_config.pipeline_config(self.params, self.CONTROLLER), self.kinematics,
                               control_config.reference(self.params))

    # --- inputs: judge, then store ---------------------------------------------------------
    def on_ball_state(self, msg: BallState, info: dict) -> None:
        now_ns = self.get_clock().now().nanoseconds
        steady = time.monotonic()
        # rclpy's MessageInfo: the writer's sequence number (publisher_gid only in newer rclpy)
        seq, gid = info.get("publication_sequence_number"), info.get("publisher_gid")
        # a lock is taken only on a publisher the graph lists alone (never on one of two)
        publishers = self._check_graph(steady, force=self.source.may_move(steady))
        ours, event = self.source.observe(steady, seq, gid, relock_allowed=len(publishers) == 1)
        if event == "locked" and self._publishers == [UNNAMED]:
            self._next_graph_check_s = steady    # the name follows on a later graph check
        if event == "locked":
            self._locked_name = self._publishers[0] if self._publishers != [UNNAMED] else ""
            self.get_logger().info(f"using /ball_state from {self._locked_name or 'its publisher'}")
        if not ours:
            self._refuse("foreign", self._foreign_reason(event))
            return
        stamp_ns = _stamp_ns(msg.header.stamp)
        verdict = self.gate.check(now_ns * 1e-9, stamp_ns * 1e-9, self._observation(msg, 0.0, 0.0))
        if not verdict.ok:
            self._refuse(verdict.kind, verdict.reason)
            return
        self._arrival_ages_s.append(now_ns * 1e-9 - stamp_ns * 1e-9)
        if self._last_state_s is not None:
            interval = min(max(steady - self._last_state_s, 0.0), 0.5)
            self._state_interval_s += 0.1 * (interval - self._state_interval_s)
        self._last_state_s = steady
        std = self._pose_std.pop(stamp_ns, None)
        if std is None and self._plate_pose_published:
            # the pose of this frame is on its way: step when it arrives (or the watchdog gives up)
            self._waiting_for_pose, self._waiting_since_s = msg, steady
            return
        self._use(msg, std or 0.0, steady)

    def on_level_offset(self, msg: Vector3Stamped) -> None:
        if math.isfinite(msg.vector.x) and math.isfinite(msg.vector.y):
            self._level = (_stamp_ns(msg.header.stamp), (msg.vector.x, msg.vector.y))

    def _level_for(self, stamp_ns: int):
        """The tracker's level offset for a ball state stamped stamp_ns, None without a recent one."""
        if self._level is None or abs(stamp_ns - self._level[0]) > LEVEL_OFFSET_MAX_AGE_S * 1e9:
            return None
        return self._level[1]

    def on_plate_pose(self, msg: PoseWithCovarianceStamped) -> None:
        std = ball_position_std_m(msg.pose.covariance)
        stamp_ns = _stamp_ns(msg.header.stamp)
        waiting = self._waiting_for_pose
        if waiting is not None and _stamp_ns(waiting.header.stamp) == stamp_ns:
            self._use(waiting, std, time.monotonic())
            return
        self._pose_std[stamp_ns] = std
        while len(self._pose_std) > 16:
            self._pose_std.popitem(last=False)

    def _use(self, msg: BallState, std: float, steady: float) -> None:
        self._waiting_for_pose = None
        self._ball, self._ball_std_m = msg, std
        if self._event_driven:
            self._last_state_step_s = steady
            self._steps["state"] += 1
            self.control_step(steady)

    def _refuse(self, kind: str, reason: str) -> None:
        self.refusals[kind] += 1
        self.dropped_ball_states += 1
        counts = ", ".join(f"{k} {n}" for k, n in sorted(self.refusals.items()))
        self.get_logger().warn(f"/ball_state refused: {reason} (refused so far: {counts})",
                               throttle_duration_sec=2.0)

    def _foreign_reason(self, event: str) -> str:
        others = [n for n in self._publishers if n != self._locked_name] or ["an unlisted publisher"]
        if event == "ambiguous" and not self._publishers:
            return "its publisher is not in the ROS graph yet"
        if event == "ambiguous":
            return (f"no publisher in use and {len(self._publishers)} publish on /ball_state "
                    f"({', '.join(self._publishers)}): not choosing one")
        return (f"from a second publisher ({', '.join(others)}); using {self._locked_name or 'the first one'}")

    def _check_graph(self, steady: float, force: bool = False) -> list:
        """Publisher names on /ball_state (refreshed at most once per GRAPH_CHECK_PERIOD_S)."""
        if force or steady >= self._next_graph_check_s:
            self._next_graph_check_s = steady + GRAPH_CHECK_PERIOD_S
            # a publisher whose node is not known yet (discovery in progress) counts, unnamed
            names = sorted(f"{i.node_namespace.rstrip('/')}/{i.node_name}" if "_UNKNOWN_" not in i.node_name
                           else UNNAMED for i in self.get_publishers_info_by_topic(BALL_TOPIC))
            if len(names) > 1 and names != self._publishers:
                listed = ", ".join(n + (" (in use)" if n == self._locked_name else " (ignored)") for n in names)
                self.get_logger().warn(f"{len(names)} publishers on /ball_state: {listed}")
            self._publishers = names
            if not self._locked_name and self.source.locked_key is not None and names in ([UNNAMED], []):
                self._next_graph_check_s = steady + 0.1   # name it as soon as the graph can
            elif not self._locked_name and self.source.locked_key is not None and len(names) == 1:
                self._locked_name = names[0]
                self.get_logger().info(f"using /ball_state from {self._locked_name}")
            self._plate_pose_published = self.count_publishers(PLATE_POSE_TOPIC) > 0
        return self._publishers

    def on_joint_states(self, msg: JointState) -> None:
        index = {name: i for i, name in enumerate(msg.name)}
        try:
            q = np.array([msg.position[index[n]] for n in JOINT_NAMES], dtype=float)
        except (KeyError, IndexError):
            self.get_logger().warn(f"/joint_states lacks some of {list(JOINT_NAMES)}; ignored",
                                   throttle_duration_sec=5.0)
            return
        if np.all(np.isfinite(q)):
            self._q = q
            self.joint_beat.beat(time.monotonic())

    def on_set_parameters(self, params) -> SetParametersResult:
        updated = dict(self.params)
        try:
            for p in params:
                if p.name not in self._schema:
                    continue
                if p.name not in control_config.RUNTIME_PARAMETERS:
                    return SetParametersResult(successful=False, reason=f"'{p.name}' is read-only at run time")
                updated[p.name] = self._schema[p.name].validate(p.value)
            reference = control_config.reference(updated)
        except (ParameterError, ReferenceError) as error:
            return SetParametersResult(successful=False, reason=str(error))
        self.params = updated
        self.pipeline.set_reference(reference)
        if self.CONTROLLER == "pid":
            self.pipeline.set_pid_gains(control_config.pid_gains(updated))
        return SetParametersResult(successful=True)

    # --- watchdogs ---------------------------------------------------------------------------
    def on_tick(self) -> None:
        """The control_rate_hz timer: every step ('timer'), or only while states are missing."""
        steady = time.monotonic()
        if self._waiting_for_pose is not None and steady - self._waiting_since_s > self._period_s:
            self._use(self._waiting_for_pose, 0.0, steady)   # no /plate_pose for it: markers rule
            if self._event_driven:
                return
        if self._event_driven:
            # states are coming: they trigger the steps; missing for 1.5 intervals: step here
            hold_after = min(max(1.5 * self._state_interval_s, self._period_s), 0.1)
            if steady - self._last_state_step_s < hold_after:
                return
        self._steps["timer"] += 1
        self.control_step(steady)

    def on_watchdog(self) -> None:
        """Steady clock: is /joint_states coming, does the (simulated) clock move, new publishers?"""
        steady = time.monotonic()
        self._check_graph(steady)
        if steady >= self._next_report_s:
            self._next_report_s = steady + STATS_PERIOD_S
            self.log_statistics()
        self.statistics.publish()   # values are read only when someone subscribes
        if self._sim_time:
            now_ns = self.get_clock().now().nanoseconds
            if now_ns != self._clock_seen_ns:
                if self._clock_seen_ns is not None and now_ns < self._clock_seen_ns - 1_000_000 and self._q is not None:
                    self.get_logger().warn(f"time went back {(self._clock_seen_ns - now_ns) * 1e-9:.2f} s "
                                           "(a simulation reset?): starting over from homing")
                    self.restart()
                if self._clock_seen_ns is not None or now_ns > 0:
                    self.clock_beat.beat(steady)
                self._clock_seen_ns = now_ns
        lost = []
        for name, beat in (("/joint_states", self.joint_beat), ("/clock", self.clock_beat)):
            change = beat.check(steady)
            if change == "lost":
                self.get_logger().error(f"no {name} for {steady - beat.last_s:.1f} s: commands stopped until it "
                                        "returns (the arm holds where it is)")
            elif change == "back":
                self.get_logger().info(f"{name} is back")
            if beat.lost:
                lost.append(name)
        if lost:
            self.stopped_reason = f"no {' and '.join(lost)}"
            if steady - self._last_stop_note_s > 5.0:
                self._last_stop_note_s = steady
                self.get_logger().warn(f"commands stopped: {self.stopped_reason}")
        elif self.stopped_reason:
            self.get_logger().info(f"resuming after '{self.stopped_reason}': homing from the measured joints")
            self.restart()

    def on_diagnostics(self) -> None:
        """Every DIAGNOSTICS_PERIOD_S (steady clock): the plant estimate on /diagnostics."""
        values = {name: float(getter()) for name, getter in self._plant_entries}
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.status.append(DiagnosticStatus(
            level=DiagnosticStatus.OK, name=f"{self.get_name()}: Plant Estimate",
            message=level_offset_summary(values["disturbance_tilt_x_deg"], values["disturbance_tilt_y_deg"]),
            hardware_id=self.get_fully_qualified_name(),
            values=[KeyValue(key=name, value=f"{value:.4f}") for name, value in values.items()]))
        try:
            self.diagnostics_pub.publish(msg)
        except Exception:  # noqa: BLE001 - rclpy raises RCLError when the context went away
            if self.context.ok():
                raise

    def log_statistics(self) -> None:
        """Every STATS_PERIOD_S: steps by trigger and how old states are when they arrive."""
        if not self._steps and not self._arrival_ages_s:
            return
        ages = np.array(self._arrival_ages_s) * 1e3 if self._arrival_ages_s else np.zeros(1)
        self.get_logger().info(
            f"last {STATS_PERIOD_S:.0f} s: {self._steps['state']} steps on new states, {self._steps['timer']} by the "
            f"timer; state age on arrival p50 {np.percentile(ages, 50):.0f} ms, p95 {np.percentile(ages, 95):.0f} ms "
            f"(negative: stamped ahead of this node's clock)")
        self._steps.clear()
        self._arrival_ages_s.clear()

    def restart(self) -> None:
        """Start over from homing at the measured joints, with no memory of the state before."""
        self.stopped_reason = ""
        self.pipeline = self.make_pipeline()
        self.gate.reset()
        self._ball, self._waiting_for_pose, self._mode = None, None, None
        self._last_now_ns = None

    # --- the control step ------------------------------------------------------------------
    def control_step(self, steady: float) -> None:
        if not self.context.ok() or self.stopped_reason:
            return  # shutting down, or a dead peer: publish nothing
        if self._q is None:
            self.get_logger().info("waiting for /joint_states before commanding", throttle_duration_sec=5.0)
            return
        now = self.get_clock().now()
        if self._last_now_ns is not None and now.nanoseconds < self._last_now_ns - 1_000_000:
            self.get_logger().warn(f"time went back {(self._last_now_ns - now.nanoseconds) * 1e-9:.2f} s "
                                   "(a simulation reset?): starting over from homing")
            self.restart()
        self._last_now_ns = now.nanoseconds
        now_s = now.nanoseconds * 1e-9
        obs = None
        if self._ball is not None:
            age = max(0.0, now_s - _stamp_ns(self._ball.header.stamp) * 1e-9)
            obs = self._observation(self._ball, age, self._ball_std_m,
                                    self._level_for(_stamp_ns(self._ball.header.stamp)))
        result = self.pipeline.step(now_s, obs, self._q)
        self.ticks += 1
        self.log_mode(result)
        try:
            self.publish_outputs(result, now.to_msg())
        except Exception:  # noqa: BLE001 - rclpy raises RCLError when the context went away
            if self.context.ok():
                raise

    @staticmethod
    def _observation(msg: BallState, age_s: float, std_m: float, level_offset_rad=None) -> BallObservation:
        return BallObservation(msg.x, msg.y, msg.vx, msg.vy, msg.tracking_valid, msg.markers_found, age_s,
                               position_std_m=std_m, level_offset_rad=level_offset_rad)

    def log_mode(self, result) -> None:
        if result.mode != self._mode:
            self.get_logger().info(f"mode {result.mode.value}: {self.pipeline.safety.reason}")
            self._mode = result.mode
        elif result.mode in (Mode.HOLDING, Mode.RETURNING):
            self.get_logger().warn(f"{result.mode.value}: {self.pipeline.safety.reason}", throttle_duration_sec=2.0)
        if result.refused:
            self.get_logger().error(f"refused a non-finite/out-of-limit command ({self.pipeline.refused_count})",
                                    throttle_duration_sec=2.0)

    def publish_outputs(self, result, stamp) -> None:
        self.publish_joints(result.q_cmd, stamp)
        cmd = Vector3Stamped()
        cmd.header.stamp, cmd.header.frame_id = stamp, PLATE_FRAME
        cmd.vector.x, cmd.vector.y = result.plate_cmd
        self.plate_cmd_pub.publish(cmd)
        if result.target_m is not None:
            ref = PointStamped()
            ref.header.stamp, ref.header.frame_id = stamp, PLATE_FRAME
            ref.point.x, ref.point.y = result.target_m
            self.reference_pub.publish(ref)

    def publish_joints(self, q_cmd: np.ndarray, stamp) -> None:
        raise NotImplementedError
