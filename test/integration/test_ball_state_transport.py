"""BallState between processes: our message, real DDS, the test's private domain."""
import textwrap

from ball_tracker_msgs.msg import BallState
from rclpy.qos import qos_profile_sensor_data

from harness import python_cmd

PUBLISHER = textwrap.dedent("""
    import rclpy, time
    from ball_tracker_msgs.msg import BallState
    from rclpy.qos import qos_profile_sensor_data
    rclpy.init()
    node = rclpy.create_node('ball_state_source')
    pub = node.create_publisher(BallState, '/ball_state', qos_profile_sensor_data)
    msg = BallState(x=0.125, y=-0.0625, vx=0.5, vy=-0.25, ball_found=True, tracking_valid=True,
                    markers_found=3, pixel_u=320.5, pixel_v=240.25)
    msg.header.frame_id = 'plate_center'
    while rclpy.ok():
        pub.publish(msg)
        time.sleep(0.05)
""")


def test_ball_state_crosses_processes_with_every_field(launcher, graph):
    launcher.start(python_cmd("-c", PUBLISHER), name="publisher")
    (msg,) = graph.collect(BallState, "/ball_state", qos=qos_profile_sensor_data, timeout=30)
    assert (msg.x, msg.y, msg.vx, msg.vy) == (0.125, -0.0625, 0.5, -0.25)
    assert msg.ball_found and msg.tracking_valid and msg.markers_found == 3
    assert (msg.pixel_u, msg.pixel_v) == (320.5, 240.25)
    assert msg.header.frame_id == "plate_center"
