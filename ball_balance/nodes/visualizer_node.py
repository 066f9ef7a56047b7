"""`ball_balance_visualizer`: RViz markers of the balancing scene (docs/design.md section 4).

Subscribes /ball_state (sensor-data QoS) and /ball_reference (geometry_msgs/PointStamped)
and publishes visualization_msgs/MarkerArray on /ball_balance_visualization, all in
`plate_center`, at `rate_hz`:
  ns "plate"      the plate (CUBE, 0.457 m square)
  ns "ball"       the ball (SPHERE; orange while tracking_valid, grey when not)
  ns "velocity"   ARROW from the ball along its velocity (`velocity_scale_s` m per m/s)
  ns "reference"  the reference path (LINE_STRIP): from reference_* parameters when
                  reference_kind is set, else the recent /ball_reference targets
  ns "target"     the current target (small SPHERE)
  ns "trail"      the last `trail_length` ball positions (LINE_STRIP)

Stamps: the markers are drawn in the moving `plate_center` frame, so RViz must look up
base_link -> plate_center at their stamp. A marker stamped "now" is ahead of the newest /tf
(robot_state_publisher stamps /tf with the joint states' time, which lags), and RViz then
waits or reports extrapolation. The markers carry the newest /tf stamp instead, or the ball
state's capture stamp when that is older (the scene as the camera saw it); never a time TF
cannot resolve. Before any /tf arrives the stamp is zero ("the latest transform").
"""
from __future__ import annotations

from collections import deque

from ball_tracker_msgs.msg import BallState
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Point, PointStamped
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from std_msgs.msg import ColorRGBA
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import Marker, MarkerArray

from ball_balance.control import config as control_config
from ball_balance.control.references import ReferenceError
from ball_balance.plate_geometry import BALL_RADIUS_M, PLATE_FRAME, PLATE_SIDE_M, PLATE_THICKNESS_M
from controller_manager_py.parameters import Param, declare_parameters
from controller_manager_py.ros.node_main import StartupError, main_for

SCHEMA = [
    Param("rate_hz", 20.0, "marker publishing rate", "Hz", 1.0, 100.0, read_only=True, user_facing=True),
    Param("trail_length", 150, "ball positions kept in the trail", "", 2, 5000, read_only=True),
    Param("velocity_scale_s", 0.5, "arrow length per unit speed", "m/(m/s)", 0.0, 10.0, read_only=True),
    Param("reference_kind", "", "draw this reference's path ('' = the recent /ball_reference targets)",
          choices=("",) + tuple(control_config.REFERENCE_SCHEMA[0].choices), read_only=True, user_facing=True),
] + [p for p in control_config.REFERENCE_SCHEMA if p.name != "reference_kind"]

Z_TOP = PLATE_THICKNESS_M / 2.0
# A ball state older than this (relative to the newest /tf) no longer sets the stamp: the
# tracker stopped, and TF buffers keep only the last few seconds.
BALL_STAMP_MAX_LAG_NS = 1_000_000_000


def _ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def marker_stamp_ns(newest_tf_ns: int, ball_stamp_ns: int = 0) -> int:
    """The stamp TF can resolve (see the module docstring); 0 means "latest transform"."""
    if newest_tf_ns <= 0:
        return 0
    if newest_tf_ns - BALL_STAMP_MAX_LAG_NS <= ball_stamp_ns < newest_tf_ns:
        return ball_stamp_ns
    return newest_tf_ns


def _color(r, g, b, a=1.0) -> ColorRGBA:
    return ColorRGBA(r=float(r), g=float(g), b=float(b), a=float(a))


class VisualizerNode(Node):
    def __init__(self):
        super().__init__("ball_balance_visualizer")
        self.params = declare_parameters(self, SCHEMA)
        self.fixed_path = None
        if self.params["reference_kind"]:
            values = dict(self.params)
            try:
                self.fixed_path = control_config.reference(values).path_points(200)
            except ReferenceError as error:
                raise StartupError(str(error)) from None
        self.ball = None
        self.target = None
        self.trail = deque(maxlen=self.params["trail_length"])
        self.targets = deque(maxlen=400)
        self.newest_tf_ns = 0
        self.create_subscription(BallState, "/ball_state", self.on_ball_state, qos_profile_sensor_data)
        self.create_subscription(PointStamped, "/ball_reference", self.on_reference, 10)
        self.create_subscription(TFMessage, "/tf", self.on_tf, 10)
        self.pub = self.create_publisher(MarkerArray, "/ball_balance_visualization", 10)
        self.create_timer(1.0 / self.params["rate_hz"], self.on_timer)

    def announce(self) -> None:
        """The start-up line (controller_manager_py.ros.node_main.run_node)."""
        path = f"the {self.params['reference_kind']} reference" if self.fixed_path is not None else "/ball_reference"
        self.get_logger().info(f"markers of /ball_state and {path} on /ball_balance_visualization "
                               f"(frame {PLATE_FRAME}) at {self.params['rate_hz']:g} Hz")

    def on_ball_state(self, msg: BallState) -> None:
        if all(v == v and abs(v) < 1.0 for v in (msg.x, msg.y, msg.vx, msg.vy)):  # finite, sane
            self.ball = msg
            self.trail.append((msg.x, msg.y))

    def on_tf(self, msg: TFMessage) -> None:
        for transform in msg.transforms:
            self.newest_tf_ns = max(self.newest_tf_ns, _ns(transform.header.stamp))

    def on_reference(self, msg: PointStamped) -> None:
        self.target = (msg.point.x, msg.point.y)
        self.targets.append(self.target)

    def _marker(self, ns, kind, stamp) -> Marker:
        m = Marker(ns=ns, id=0, type=kind, action=Marker.ADD)
        m.header.frame_id, m.header.stamp = PLATE_FRAME, stamp
        m.pose.orientation.w = 1.0
        m.lifetime = Duration(sec=1)
        return m

    def on_timer(self) -> None:
        if not self.context.ok():
            return  # shutting down
        try:
            self.publish_markers()
        except Exception:  # noqa: BLE001 - rclpy raises RCLError when the context went away
            if self.context.ok():
                raise

    def publish_markers(self) -> None:
        ball_ns = _ns(self.ball.header.stamp) if self.ball is not None else 0
        sec, nanosec = divmod(marker_stamp_ns(self.newest_tf_ns, ball_ns), 1_000_000_000)
        stamp = Time(sec=sec, nanosec=nanosec)
        markers = []
        plate = self._marker("plate", Marker.CUBE, stamp)
        plate.scale.x = plate.scale.y = PLATE_SIDE_M
        plate.scale.z = PLATE_THICKNESS_M
        plate.color = _color(0.93, 0.93, 0.91, 0.8)
        markers.append(plate)
        if self.ball is not None:
            b = self.ball
            ball = self._marker("ball", Marker.SPHERE, stamp)
            ball.pose.position = Point(x=b.x, y=b.y, z=Z_TOP + BALL_RADIUS_M)
            ball.scale.x = ball.scale.y = ball.scale.z = 2 * BALL_RADIUS_M
            ball.color = _color(1.0, 0.45, 0.0) if b.tracking_valid else _color(0.5, 0.5, 0.5)
            arrow = self._marker("velocity", Marker.ARROW, stamp)
            k = self.params["velocity_scale_s"]
            z = Z_TOP + 2 * BALL_RADIUS_M + 0.005
            arrow.points = [Point(x=b.x, y=b.y, z=z), Point(x=b.x + k * b.vx, y=b.y + k * b.vy, z=z)]
            arrow.scale.x, arrow.scale.y, arrow.scale.z = 0.006, 0.012, 0.012
            arrow.color = _color(0.1, 0.4, 1.0)
            markers += [ball, arrow]
        if len(self.trail) >= 2:
            markers.append(self._strip("trail", self.trail, _color(1.0, 0.6, 0.2, 0.7), stamp))
        path = self.fixed_path if self.fixed_path is not None else self.targets
        if len(path) >= 2:
            markers.append(self._strip("reference", path, _color(0.1, 0.8, 0.2, 0.9), stamp))
        if self.target is not None:
            target = self._marker("target", Marker.SPHERE, stamp)
            target.pose.position = Point(x=self.target[0], y=self.target[1], z=Z_TOP + 0.002)
            target.scale.x = target.scale.y = target.scale.z = 0.015
            target.color = _color(0.1, 0.8, 0.2)
            markers.append(target)
        self.pub.publish(MarkerArray(markers=markers))

    def _strip(self, ns, points, color, stamp) -> Marker:
        m = self._marker(ns, Marker.LINE_STRIP, stamp)
        m.points = [Point(x=float(x), y=float(y), z=Z_TOP + 0.001) for x, y in points]
        m.scale.x = 0.003
        m.color = color
        return m


main = main_for(VisualizerNode)
