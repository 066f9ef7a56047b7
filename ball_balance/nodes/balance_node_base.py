"""What the PID and MPC nodes share: subscriptions, the control timer, safety logging,
run-time parameter changes and the common outputs. Subclasses set SCHEMA, CONTROLLER and
`publish_joints()` (forward position commands vs a single-point trajectory).

Inputs
  /ball_state    ball_tracker_msgs/BallState (sensor-data QoS): the ball, plate frame.
  /joint_states  sensor_msgs/JointState: the arm's current joint positions.
Outputs
  /plate_cmd      geometry_msgs/Vector3Stamped, frame plate_center: x = u_x, y = u_y [rad]
                  (z = 0), the commanded tilt, for the tracker's Kalman feed-forward.
  /ball_reference geometry_msgs/PointStamped, frame plate_center: the current target (z = 0)
                  while engaged; not published otherwise.

Plate pose: forward kinematics of /joint_states through the robot description (the same
file robot_state_publisher serves on /tf), not a TF lookup: it has no TF latency, cannot
be missing once joint states arrive, and is exactly what robot_state_publisher would
publish for base_link -> plate_center. Until the first /joint_states nothing is commanded
(so the first command can never jump); a joint_states message lacking one of our joints is
ignored with a throttled warning.

Timer callback (the hot path): reads the latest slot values, runs ControlPipeline.step,
publishes. Callbacks only validate and store. Logging is throttled or on mode changes.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
from ball_tracker_msgs.msg import BallState
from geometry_msgs.msg import PointStamped, Vector3Stamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState

from ball_balance.control import config as control_config
from ball_balance.control.kinematics import Chain, KinematicsError
from ball_balance.control.pipeline import ControlPipeline
from ball_balance.control.references import ReferenceError
from ball_balance.control.safety import BallObservation, Mode
from ball_balance.plate_geometry import PLATE_FRAME
from ball_balance.robot import JOINT_NAMES, RobotDescriptionError, robot_description_path
from ball_balance.ros.node_main import StartupError
from controller_manager_py.parameters import ParameterError, declare_parameters


class BalanceControllerNode(Node):
    SCHEMA: list = []
    CONTROLLER = "pid"

    def __init__(self, name: str):
        super().__init__(name)
        self.params = dict(declare_parameters(self, self.SCHEMA))
        self._schema = {p.name: p for p in self.SCHEMA}
        try:
            urdf = robot_description_path().read_text()
            chain = Chain.from_urdf(urdf, JOINT_NAMES)
            kin = control_config.plate_kinematics(chain, self.params)
            reference = control_config.reference(self.params)
        except (RobotDescriptionError, KinematicsError, ReferenceError, OSError) as error:
            raise StartupError(str(error)) from None
        self.pipeline = ControlPipeline(control_config.pipeline_config(self.params, self.CONTROLLER),
                                        kin, reference)
        self._ball: Optional[BallState] = None
        self._q: Optional[np.ndarray] = None
        self._mode: Optional[Mode] = None
        self.dropped_ball_states = 0
        self.ticks = 0

        self.create_subscription(BallState, "/ball_state", self.on_ball_state, qos_profile_sensor_data)
        self.create_subscription(JointState, "/joint_states", self.on_joint_states, 10)
        self.plate_cmd_pub = self.create_publisher(Vector3Stamped, "/plate_cmd", 10)
        self.reference_pub = self.create_publisher(PointStamped, "/ball_reference", 10)
        self.add_on_set_parameters_callback(self.on_set_parameters)
        self.timer = self.create_timer(1.0 / self.params["control_rate_hz"], self.on_tick)
        self.get_logger().info(
            f"{self.CONTROLLER.upper()} balance controller at {self.params['control_rate_hz']:.0f} Hz, "
            f"reference {self.params['reference_kind']}; waiting for /joint_states and /ball_state")

    # --- callbacks: validate and store ---------------------------------------------------
    def on_ball_state(self, msg: BallState) -> None:
        if not all(math.isfinite(v) for v in (msg.x, msg.y, msg.vx, msg.vy)):
            self.dropped_ball_states += 1
            self.get_logger().warn(f"non-finite BallState ignored ({self.dropped_ball_states} so far)",
                                   throttle_duration_sec=2.0)
            return  # the last good state ages and goes stale: hold, then home
        self._ball = msg

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

    # --- the control tick -----------------------------------------------------------------
    def on_tick(self) -> None:
        if not self.context.ok():
            return  # shutting down (SIGTERM/Ctrl-C): publishing would fail
        if self._q is None:
            self.get_logger().info("waiting for /joint_states before commanding", throttle_duration_sec=5.0)
            return
        now = self.get_clock().now()
        now_s = now.nanoseconds * 1e-9
        obs = None
        if self._ball is not None:
            b = self._ball
            stamp_s = b.header.stamp.sec + b.header.stamp.nanosec * 1e-9
            obs = BallObservation(b.x, b.y, b.vx, b.vy, b.tracking_valid, b.markers_found,
                                  max(0.0, now_s - stamp_s))
        result = self.pipeline.step(now_s, obs, self._q)
        self.ticks += 1
        if result.mode != self._mode:
            self.get_logger().info(f"mode {result.mode.value}: {self.pipeline.safety.reason}")
            self._mode = result.mode
        elif result.mode in (Mode.HOLDING, Mode.RETURNING):
            self.get_logger().warn(f"{result.mode.value}: {self.pipeline.safety.reason}", throttle_duration_sec=2.0)
        if result.refused:
            self.get_logger().error(f"refused a non-finite/out-of-limit command ({self.pipeline.refused_count})",
                                    throttle_duration_sec=2.0)
        try:
            self.publish_outputs(result, now.to_msg())
        except Exception:  # noqa: BLE001 - rclpy raises RCLError when the context went away
            if self.context.ok():
                raise

    def publish_outputs(self, result, stamp) -> None:
        self.publish_joints(result.q_cmd, stamp)
        cmd = Vector3Stamped()
        cmd.header.stamp, cmd.header.frame_id = stamp, PLATE_FRAME
        cmd.vector.x, cmd.vector.y = result.u
        self.plate_cmd_pub.publish(cmd)
        if result.ref is not None:
            ref = PointStamped()
            ref.header.stamp, ref.header.frame_id = stamp, PLATE_FRAME
            ref.point.x, ref.point.y = float(result.ref.p[0]), float(result.ref.p[1])
            self.reference_pub.publish(ref)

    def publish_joints(self, q_cmd: np.ndarray, stamp) -> None:
        raise NotImplementedError
