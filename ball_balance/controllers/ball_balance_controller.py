"""ball_balance_controllers/BallBalanceController: the whole balance loop inside the controller manager.

The same control pipeline as the balance nodes (ball_balance/control/pipeline.py: safety ->
latency prediction -> reference -> tilt law -> IK -> shaping -> guard), with the tilt law
chosen by `tilt_law` (policy | pid | mpc), run as a controller: the joints' position state
interfaces are the measured arm, the six position command interfaces take the shaped joint
targets. No /joint_states round trip and no separate node between the ball and the arm.

Parameters: every parameter of the balance nodes (ball_balance/control/config.py, the one
schema: reference, PID gains, MPC weights, policy model, safety, shaping) except the nodes'
own triggering (control_trigger, joint_states_timeout_s: joint states never go missing
here), plus `async_step`. Two rates:
  - `control_rate_hz` (the schema's 50; config/ur_controllers_policy.yaml 60, the policy's): a
    pipeline step (safety, prediction, tilt law, IK, shaping) every 1/control_rate_hz of the
    manager's time, as the nodes' timer; the policy's history and the shaping's step limit are
    per step, and the model's rate is checked against it. The steps keep to that grid: each
    runs at the first update at or after its time, so with an update rate that is not a whole
    multiple (500 Hz and 60 Hz) a step is up to one update period late, never drifts, and the
    average rate is control_rate_hz.
  - `update_rate` (0: the manager's, 500 Hz): every update writes the newest step's joint
    target to the six command interfaces, moved towards it within the URDF joint velocity
    limits for that update's period (manager/joint_limits.JointLimiter). With `command_ramp`
    (default) the written command runs from the last one to the target in a straight line
    over one control period (controller_manager_py.controllers.command_ramp.CommandRamp): a target jumping once per step
    shakes the plate at the control rate and can throw the ball off it after a push. Why every update: the
    manager's limits stage writes the saturated value back into the command interface (as
    ros2_control's does), so a target written only once per step would be cut to one manager
    cycle's worth of joint motion (3.14 rad/s x 2 ms = 6.3 mrad of a step of up to 20 mrad)
    and the rest lost: the plate would lag the pipeline's commands and the ball swing.
    The nodes need no such care: forward_position_controller writes its held target every cycle.
With `async_step` (default) each step runs in a worker thread (manager/async_handler): update()
hands over the measured joints and the newest ball state and never waits for the policy's
inference or the MPC's solve; the step's target is written from the first update after it is
ready. A step due while the previous one still runs is missed (`missed_steps`, the target is
kept). Leave the manager's `is_async` false: update() itself is a few microseconds.
The pipeline (and the policy model) is built at configure, where a model that does not fit
(or an update rate below control_rate_hz) is refused with one line; it
starts over from the measured joints on every activation and when the clock goes back (a
simulation reset).

Inputs (controller node, non-real-time executor):
  /ball_state  ball_tracker_msgs/BallState (sensor-data QoS, newest only). Each message is
               judged on arrival by the nodes' plausibility gate (control/plausibility.py:
               non-finite, future, old, off the plate, too fast, jumps); a refused one is
               counted and logged (throttled) and never displaces the accepted state, which
               reaches update() through a single slot (one reference assignment, no lock).
  /plate_pose  geometry_msgs/PoseWithCovarianceStamped (optional): the pose fit's covariance
               of the frame with the same stamp gives the state's position_std_m; without it
               the min_markers rule decides (as in the nodes). A pose arriving after its update
               step applies from the next step.
  /ball_level_offset  geometry_msgs/Vector3Stamped (optional): the tracker's constant
               disturbance as a plate-level offset [rad], cancelled in place of the plant
               estimate's (as in the nodes: balance_node_base).
Outputs:
  six `<joint>/position` command interfaces (config/ur_controllers_policy.yaml lists none: the
  joints are the robot's, ball_balance.robot.JOINT_NAMES);
  /plate_cmd  geometry_msgs/Vector3Stamped (plate_center, x = u_x, y = u_y [rad]; the pipeline's
              TickResult.plate_cmd: the tilt less the disturbance's level offset) for the
              tracker's feed-forward, and /ball_reference geometry_msgs/PointStamped (the
              target while engaged), as the nodes publish them, by a timer of the controller
              node (executor thread) from the newest step update() left in a slot: update()
              never publishes.
Reported: introspection `refused_ball_states` and `refused_ball_states_<kind>` (gate
refusals), `refused_commands` (the pipeline's guard: non-finite/out-of-limit joint targets
held), `refused_policy_ticks` (policy: non-finite observation or output, last tilt held),
`missed_steps` (a step due while the previous one still ran),
`mode` (0 homing, 1 ready, 2 engaged, 3 holding, 4 returning), `tilt_x_rad`, `tilt_y_rad`,
`step_time_us`, and the plant estimate `disturbance_tilt_x_deg`, `disturbance_tilt_y_deg` (the
disturbance as a plate-level offset, asin(d / (k g))) and `plant_gain_ratio` (as the nodes'
~/statistics); the refused_* and missed_* counters also show in /diagnostics (WARN while they grow),
and so does the plant estimate (values of the manager's "Controllers Activity" status).
"""
from __future__ import annotations

import dataclasses
import math
import time as _time
from collections import Counter, OrderedDict
from typing import NamedTuple, Optional

import numpy as np

from ball_balance.control import config as control_config
from ball_balance.control.estimation import plant_statistics
from ball_balance.control.kinematics import Chain, KinematicsError
from ball_balance.control.pipeline import CONTROLLERS, ControlPipeline
from ball_balance.control.plausibility import BallStateGate, gate_config
from ball_balance.control.references import ReferenceError
from ball_balance.control.safety import LEVEL_OFFSET_MAX_AGE_S, LEVEL_OFFSET_TOPIC, BallObservation, Mode
from ball_balance.plate_geometry import PLATE_FRAME, PLATE_SIDE_M
from ball_balance.policy.params import POLICY_PARAMS
from ball_balance.robot import JOINT_NAMES
from controller_manager_py.controller_interface.base import (
    ControllerInterface,
    InterfaceConfiguration,
    interface_configuration_type,
)
from controller_manager_py.controllers.command_ramp import CommandRamp
from controller_manager_py.controllers.policy_model import PolicyModelError
from controller_manager_py.hardware_interface.types import CallbackReturn, State, return_type
from controller_manager_py.manager.async_handler import AsyncHandler
from controller_manager_py.manager.joint_limits import JointLimiter, limits_from_description
from controller_manager_py.manager.throttle import Throttle
from controller_manager_py.parameters import Param

# the nodes' own triggering: here steps follow the manager's clock and the joints are state interfaces
NODE_ONLY = {"control_trigger", "joint_states_timeout_s"}
GATE_KINDS = ("non_finite", "future", "stale", "old", "off_plate", "too_fast", "jump")
# The worker holds Python's interpreter lock while it steps (1-3 ms of Python): preempted there by
# another process, it would keep the manager's loop (SCHED_FIFO 50) waiting for that lock for as
# long. Below the loop, above the manager's executor thread (40).
STEP_THREAD_PRIORITY = 45
VELOCITY_MARGIN = 1e-6   # relative: the joint targets move this much slower than the URDF allows
MODE_CODE = {Mode.HOMING: 0.0, Mode.READY: 1.0, Mode.ENGAGED: 2.0, Mode.HOLDING: 3.0, Mode.RETURNING: 4.0}


def _schema() -> tuple:
    """The balance nodes' parameters (PID, MPC and policy schemas: one source), once each."""
    seen, params = set(), [Param("tilt_law", "policy", "the tilt law: the learned policy (PID + ONNX "
                                 "correction), the PID or the MPC", choices=CONTROLLERS, user_facing=True),
                           Param("command_ramp", True, "write the joint command as a ramp from the last "
                                 "command to the step's target over one control period (false: the target "
                                 "at once, a staircase at control_rate_hz that makes the ball hop)"),
                           Param("async_step", True, "run each control step in a worker thread (update() "
                                 "never waits for it; a step due while the last one runs is missed)"),
                           Param("step_thread_priority", STEP_THREAD_PRIORITY, "SCHED_FIFO priority of the "
                                 "async_step worker thread (0: normal scheduling)", min=0, max=99),
                           Param("step_thread_on_loop_cpu", True, "the async_step worker runs on the manager "
                                 "loop thread's CPU(s): below the loop's priority it then steps only while the "
                                 "loop sleeps and never takes Python's interpreter lock from a running cycle")]
    for p in (control_config.PID_SCHEMA + control_config.MPC_SCHEMA + POLICY_PARAMS):
        if p.name not in seen and p.name not in NODE_ONLY:
            seen.add(p.name)
            params.append(p)
    return tuple(params)


class BallSample(NamedTuple):
    """An accepted /ball_state, as update() takes it from the slot (immutable)."""

    x: float
    y: float
    vx: float
    vy: float
    valid: bool
    markers: int
    stamp_s: float
    position_std_m: float = 0.0


class BallBalanceController(ControllerInterface):
    PARAMS = _schema()

    # ---- configuration (executor thread) -----------------------------------------------
    def on_configure(self, previous_state: State) -> CallbackReturn:
        values = dict(self.params)
        self.values = values
        self.throttle = Throttle(self.get_logger())
        control_hz, update_hz = values["control_rate_hz"], self.update_rate or self.manager_update_rate
        if update_hz and update_hz < control_hz:
            self.get_logger().error(f"{self.name}: update_rate {update_hz} Hz must be at least control_rate_hz "
                                    f"{control_hz:g} Hz (a step runs in an update)")
            return CallbackReturn.ERROR
        self._control_period_s = 1.0 / control_hz
        try:
            urdf = self.get_robot_description()
            chain = Chain.from_urdf(urdf, JOINT_NAMES)
            self.kinematics = control_config.plate_kinematics(chain, values)
            self.pipeline = self.make_pipeline()
            # the URDF limits the manager's limits stage applies: the written commands stay within
            # them, by a hair (its period is the same time difference computed elsewhere: one
            # ulp more speed here would be a clamp there)
            limits = {joint: dataclasses.replace(lim, max_velocity=lim.max_velocity * (1.0 - VELOCITY_MARGIN))
                      for joint, lim in limits_from_description(urdf).items()}
            self.limiter = JointLimiter(JOINT_NAMES, limits)   # (a ramp, not an anomaly: not logged)
        except KinematicsError as error:
            self.get_logger().error(f"{self.name}: the manager's robot description has no usable base_link -> "
                                    f"plate_center chain: {error}")
            return CallbackReturn.ERROR
        except (ReferenceError, PolicyModelError, ValueError) as error:
            self.get_logger().error(f"{self.name}: {error}")
            return CallbackReturn.ERROR
        self.gate = BallStateGate(gate_config(values, PLATE_SIDE_M / 2.0, control_config.k_g(values)))
        self.refusals: Counter = Counter()
        self.refused_ball_states = 0
        self._ball: Optional[BallSample] = None       # the slot: written by callbacks, read by update()
        self._pose_std: OrderedDict = OrderedDict()  # /plate_pose stamp (ns) -> position_std_m
        self._level: Optional[tuple] = None          # (stamp s, (u_x, u_y)) of the last /ball_level_offset
        self._tilt_out = None                        # (time_s, (u_x, u_y), ref or None) for the publishers
        self._published_tilt = None
        self._fresh = True                           # the pipeline has not stepped yet
        self._restart_pending = False
        self._clock_seen = None                      # (time, steady) of the last update, for the callbacks
        self._last_time_s: Optional[float] = None
        self._next_step_s = -math.inf                # manager time the next pipeline step is due
        self._step_in = None                         # (q measured, ball observation): update() -> step
        self._target: Optional[np.ndarray] = None    # the newest step's joint target: step -> update()
        self._ramp = CommandRamp(len(JOINT_NAMES)) if values["command_ramp"] else None
        self._worker: Optional[AsyncHandler] = None
        self.missed_steps = 0
        self.mode: Optional[Mode] = None
        self.u = (0.0, 0.0)
        self.step_time_us = 0.0
        self.introspection.clear()
        self.register_introspection("refused_ball_states", lambda: float(self.refused_ball_states))
        for kind in GATE_KINDS:
            self.register_introspection(f"refused_ball_states_{kind}", lambda k=kind: float(self.refusals[k]))
        self.register_introspection("refused_commands", lambda: float(self.pipeline.refused_count))
        self.register_introspection("refused_policy_ticks",
                                    lambda: float(getattr(self.pipeline.law, "held_count", 0)))
        self.register_introspection("missed_steps", lambda: float(self.missed_steps))
        self.register_introspection("mode", lambda: MODE_CODE.get(self.mode, -1.0))
        self.register_introspection("tilt_x_rad", lambda: self.u[0])
        self.register_introspection("tilt_y_rad", lambda: self.u[1])
        self.register_introspection("step_time_us", lambda: self.step_time_us)
        for name, getter in plant_statistics(lambda: self.pipeline.plant):
            self.register_introspection(name, getter, in_diagnostics=True)
        self._create_ros_entities(control_hz)
        self.get_logger().info(f"{self.name}: {values['tilt_law']} tilt law, a step at {control_hz:g} Hz"
                               f"{' (worker thread)' if values['async_step'] else ''}, joint targets written at "
                               f"{update_hz} Hz, reference {values['reference_kind']}")
        return CallbackReturn.SUCCESS

    def make_pipeline(self) -> ControlPipeline:
        """A fresh pipeline at the parameters, built exactly as the balance nodes build theirs."""
        return ControlPipeline(control_config.pipeline_config(self.values, self.values["tilt_law"]),
                               self.kinematics, control_config.reference(self.values))

    def _create_ros_entities(self, rate: float) -> None:
        node = self.get_node()
        if node is None or getattr(self, "_subscriptions", None):
            return
        from ball_tracker_msgs.msg import BallState
        from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped, Vector3Stamped
        from rclpy.clock import Clock, ClockType
        from rclpy.qos import QoSProfile, qos_profile_sensor_data

        newest = QoSProfile(depth=1, reliability=qos_profile_sensor_data.reliability,
                            durability=qos_profile_sensor_data.durability)
        self._vector_type, self._point_type = Vector3Stamped, PointStamped
        self._subscriptions = [
            node.create_subscription(BallState, "/ball_state", self.on_ball_state, newest),
            node.create_subscription(PoseWithCovarianceStamped, "/plate_pose", self.on_plate_pose,
                                     qos_profile_sensor_data),
            node.create_subscription(Vector3Stamped, LEVEL_OFFSET_TOPIC, self.on_level_offset,
                                     qos_profile_sensor_data)]
        self._plate_cmd_pub = node.create_publisher(Vector3Stamped, "/plate_cmd", 10)
        self._reference_pub = node.create_publisher(PointStamped, "/ball_reference", 10)
        # steady clock: publishes what update() left, at the control rate, whatever the sim speed
        self._publish_timer = node.create_timer(1.0 / rate, self.publish_plate_cmd,
                                                clock=Clock(clock_type=ClockType.STEADY_TIME))

    def on_cleanup(self, previous_state: State) -> CallbackReturn:
        node = self.get_node()
        if node is not None and getattr(self, "_subscriptions", None):
            for sub in self._subscriptions:
                node.destroy_subscription(sub)
            node.destroy_publisher(self._plate_cmd_pub)
            node.destroy_publisher(self._reference_pub)
            node.destroy_timer(self._publish_timer)
            self._subscriptions = []
        return CallbackReturn.SUCCESS

    def command_interface_configuration(self) -> InterfaceConfiguration:
        return InterfaceConfiguration(interface_configuration_type.INDIVIDUAL, [f"{j}/position" for j in JOINT_NAMES])

    def state_interface_configuration(self) -> InterfaceConfiguration:
        return InterfaceConfiguration(interface_configuration_type.INDIVIDUAL, [f"{j}/position" for j in JOINT_NAMES])

    # ---- inputs (executor thread): judge, then hand over --------------------------------
    def manager_now_s(self, stamp_s: float) -> float:
        """The manager's time now (its clock: simulated when the hardware provides one), from
        the last update's time plus the steady time since, at most one control period (a
        simulation may run slower than wall time); the stamp itself before the first update."""
        seen = self._clock_seen
        if seen is None:
            return stamp_s
        time_s, steady_s = seen
        return time_s + min(_time.monotonic() - steady_s, self._control_period_s)

    def on_level_offset(self, msg) -> None:
        if math.isfinite(msg.vector.x) and math.isfinite(msg.vector.y):
            self._level = (msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9, (msg.vector.x, msg.vector.y))

    def _level_for(self, stamp_s: float):
        level = self._level
        if level is None or abs(stamp_s - level[0]) > LEVEL_OFFSET_MAX_AGE_S:
            return None
        return level[1]

    def on_ball_state(self, msg) -> None:
        # (the controller node's own clock is not the manager's: the manager does not use /clock)
        stamp_s = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        now_s = self.manager_now_s(stamp_s)
        self.offer_ball_state(BallSample(msg.x, msg.y, msg.vx, msg.vy, bool(msg.tracking_valid),
                                         int(msg.markers_found), stamp_s), now_s)

    def offer_ball_state(self, sample: BallSample, now_s: float) -> bool:
        """Judge a ball state at time now_s; a plausible one replaces the slot's (also the
        Python entry point without ROS). Returns whether it was accepted."""
        obs = BallObservation(sample.x, sample.y, sample.vx, sample.vy, sample.valid, sample.markers, 0.0)
        verdict = self.gate.check(now_s, sample.stamp_s, obs)
        if not verdict.ok:
            self.refusals[verdict.kind] += 1
            self.refused_ball_states += 1
            counts = ", ".join(f"{k} {n}" for k, n in sorted(self.refusals.items()))
            self.throttle.warn("ball_state", f"{self.name}: /ball_state refused: {verdict.reason} "
                                             f"(refused so far: {counts})")
            return False
        std = self._pose_std.pop(round(sample.stamp_s * 1e9), 0.0)
        self._ball = sample._replace(position_std_m=std)
        return True

    def on_plate_pose(self, msg) -> None:
        from ball_balance.vision.pose_quality import ball_position_std_m

        std = ball_position_std_m(msg.pose.covariance)
        stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        ball = self._ball
        if ball is not None and round(ball.stamp_s * 1e9) == stamp_ns:
            self._ball = ball._replace(position_std_m=std)
            return
        self._pose_std[stamp_ns] = std
        while len(self._pose_std) > 16:
            self._pose_std.popitem(last=False)

    def publish_plate_cmd(self) -> None:
        """Controller node timer (executor thread): the newest tilt update() computed, once."""
        out = self._tilt_out
        if out is None or out is self._published_tilt:
            return
        self._published_tilt = out
        t_s, (u_x, u_y), ref = out
        msg = self._vector_type()
        stamp_ns = round(t_s * 1e9)
        msg.header.stamp.sec, msg.header.stamp.nanosec = stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000
        msg.header.frame_id = PLATE_FRAME
        msg.vector.x, msg.vector.y = float(u_x), float(u_y)
        self._plate_cmd_pub.publish(msg)
        if ref is not None:
            point = self._point_type()
            point.header = msg.header
            point.point.x, point.point.y = float(ref[0]), float(ref[1])
            self._reference_pub.publish(point)

    # ---- activation (loop thread, between cycles): no heavy work ------------------------
    def on_activate(self, previous_state: State) -> CallbackReturn:
        self._last_time_s = None
        self._next_step_s = -math.inf
        self._target = None
        self._restart_pending = not self._fresh    # a new pipeline in the first step (worker thread)
        # ramp from what the command interfaces hold (the limits stage's last value), else the measured joints
        held = [c.value for c in self.command_interfaces]
        measured = [s.value for s in self.state_interfaces]
        self.limiter.reset([h if math.isfinite(h) else m for h, m in zip(held, measured)])
        if self.values["async_step"]:
            self._worker = AsyncHandler(f"{self.name}.step", self._step,
                                        thread_priority=self.values["step_thread_priority"],
                                        on_trigger_cpus=self.values["step_thread_on_loop_cpu"])
        return CallbackReturn.SUCCESS

    def on_deactivate(self, previous_state: State) -> CallbackReturn:
        worker, self._worker = self._worker, None
        if worker is not None:
            worker.wait_idle()
            worker.stop()
        self._tilt_out = None
        return CallbackReturn.SUCCESS

    # ---- the loop: every update writes the target; a step every control period ----------
    def update(self, time: float, period: float) -> return_type:
        if self._last_time_s is not None and time < self._last_time_s - 1e-3:
            self.get_logger().warning(f"{self.name}: time went back {self._last_time_s - time:.2f} s (a simulation "
                                      "reset?): starting over from homing")
            self._restart_pending, self._next_step_s, self._target = True, -math.inf, None
            self.limiter.reset([s.value for s in self.state_interfaces])
        self._last_time_s = time
        self._clock_seen = (time, _time.monotonic())   # one reference assignment, for the callbacks
        if time >= self._next_step_s - 1e-6:
            # on the grid of control periods; after a gap (a missed step, a slow start) from now
            self._next_step_s = max(self._next_step_s + self._control_period_s, time + 0.5 * self._control_period_s)
            worker = self._worker
            if worker is not None and worker.busy:
                self.missed_steps += 1
                self.throttle.warn("missed", f"{self.name}: a control step was due while the last one still ran "
                                             f"({self.missed_steps} missed so far): keeping its target")
            else:
                q = np.array([h.value for h in self.state_interfaces], dtype=float)
                ball = self._ball
                obs = None
                if ball is not None:
                    obs = BallObservation(ball.x, ball.y, ball.vx, ball.vy, ball.valid, ball.markers,
                                          max(0.0, time - ball.stamp_s), position_std_m=ball.position_std_m,
                                          level_offset_rad=self._level_for(ball.stamp_s))
                self._step_in = (q if np.all(np.isfinite(q)) else None, obs)
                if worker is not None:
                    worker.trigger(time, period)
                else:
                    self._step(time, period)
        target = self._target
        if target is not None and self._ramp is not None:
            if target is not self._ramp.target:   # a new step: ramp on from the command last written,
                # to reach the target in the last update before the next step
                self._ramp.retarget(target, self.limiter.previous_positions, time, period, self._next_step_s - time)
            target = self._ramp.at(time)
        if target is not None:
            for handle, value in zip(self.command_interfaces, self.limiter.limit_positions(target, period)):
                handle.value = value
        return return_type.OK

    def _step(self, time: float, period: float) -> return_type:
        """One pipeline step on the inputs update() handed over (worker thread, or inline)."""
        started = _time.perf_counter()
        if self._restart_pending:
            self.pipeline, self._restart_pending, self.mode = self.make_pipeline(), False, None
        q, obs = self._step_in
        result = self.pipeline.step(time, obs, q)
        self._fresh = False
        self._target = result.q_cmd                    # one reference assignment, for update()
        self.u = result.u
        self._tilt_out = (time, result.plate_cmd, result.target_m)
        if result.mode != self.mode:
            self.mode = result.mode
            if self.throttle.due(f"mode {result.mode.value}"):
                self.get_logger().info(f"{self.name}: mode {result.mode.value}: {self.pipeline.safety.reason}")
        if result.refused:
            self.throttle.warn("refused", f"{self.name}: refused a non-finite/out-of-limit joint command "
                                          f"({self.pipeline.refused_count} so far): holding")
        self.step_time_us = (_time.perf_counter() - started) * 1e6
        return return_type.OK
