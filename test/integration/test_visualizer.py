"""The visualizer's markers over DDS: stamped so that TF can resolve their moving frame."""
import pytest
from ball_tracker_msgs.msg import BallState
from geometry_msgs.msg import TransformStamped
from rclpy.qos import qos_profile_sensor_data
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import MarkerArray

from ball_balance.nodes.visualizer_node import marker_stamp_ns
from harness import executable

pytestmark = pytest.mark.integration
SECOND_NS = 1_000_000_000


def test_marker_stamp_is_never_ahead_of_the_newest_transform():
    newest_tf = 100 * SECOND_NS
    assert marker_stamp_ns(0, 5 * SECOND_NS) == 0                             # no /tf yet: latest
    assert marker_stamp_ns(newest_tf, newest_tf + 50_000_000) == newest_tf     # ball ahead of /tf
    assert marker_stamp_ns(newest_tf, newest_tf - 40_000_000) == newest_tf - 40_000_000  # as seen
    assert marker_stamp_ns(newest_tf, newest_tf - 5 * SECOND_NS) == newest_tf  # tracker stopped
    assert marker_stamp_ns(newest_tf) == newest_tf                             # no ball yet


def test_markers_carry_a_stamp_that_tf_has_when_the_ball_state_is_newer(launcher, graph):
    """/tf lags the camera (robot_state_publisher stamps with the joint states' time): markers
    stamped 'now' or with the ball's stamp would be ahead of every transform RViz has."""
    node = graph.node
    tf_pub = node.create_publisher(TFMessage, "/tf", 10)
    ball_pub = node.create_publisher(BallState, "/ball_state", qos_profile_sensor_data)
    tf_lag_ns = 300_000_000

    def publish():
        now_ns = node.get_clock().now().nanoseconds
        transform = TransformStamped(child_frame_id="plate_center")
        transform.header.frame_id = "base_link"
        transform.header.stamp.sec, transform.header.stamp.nanosec = divmod(now_ns - tf_lag_ns, SECOND_NS)
        transform.transform.rotation.w = 1.0
        tf_pub.publish(TFMessage(transforms=[transform]))
        ball = BallState(x=0.02, y=0.0, tracking_valid=True, ball_found=True, markers_found=4)
        ball.header.frame_id = "plate_center"
        ball.header.stamp.sec, ball.header.stamp.nanosec = divmod(now_ns - 20_000_000, SECOND_NS)
        ball_pub.publish(ball)

    node.create_timer(0.02, publish)
    launcher.start([executable("ball_balance_visualizer")])
    # once the visualizer has heard /tf (before that it stamps zero: "the latest transform")
    arrays = graph.collect(MarkerArray, "/ball_balance_visualization", count=5, timeout=30,
                           predicate=lambda m: any(k.ns == "ball" for k in m.markers)
                           and m.markers[0].header.stamp.sec > 0)
    for array in arrays:
        for marker in array.markers:
            stamp_ns = marker.header.stamp.sec * SECOND_NS + marker.header.stamp.nanosec
            now_ns = node.get_clock().now().nanoseconds
            # at or behind the newest /tf, which is tf_lag_ns behind the clock
            assert stamp_ns <= now_ns - tf_lag_ns, (marker.ns, now_ns - stamp_ns)
