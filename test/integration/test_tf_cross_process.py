"""TF across processes: our broadcasters in one process, our listener buffer in the test."""
import math
import textwrap

import pytest

from harness import executable, python_cmd

pytestmark = pytest.mark.integration

BROADCASTER = textwrap.dedent("""
    import math, rclpy
    from ball_balance.tf import Transform, quat_from_euler
    from ball_balance.tf.ros import StaticTransformBroadcaster, TransformBroadcaster, transform_to_msg
    rclpy.init()
    node = rclpy.create_node('tf_source')
    static = StaticTransformBroadcaster(node)
    # two separate calls: the static broadcaster must keep and republish both
    static.send_transform(transform_to_msg(Transform((0.0, 0.0, 1.0)), 'world', 'base'))
    static.send_transform(transform_to_msg(Transform((0.5, 0.0, 0.0)), 'base', 'tool'))
    dynamic = TransformBroadcaster(node)

    def tick():
        stamp = node.get_clock().now()
        plate = Transform((0.0, 0.0, 0.1), quat_from_euler(0.0, 0.0, math.pi / 2))
        dynamic.send_transform(transform_to_msg(plate, 'tool', 'plate', stamp.to_msg()))

    node.create_timer(0.02, tick)
    rclpy.spin(node)
""")


def test_listener_composes_static_and_dynamic_transforms_from_another_process(launcher, graph):
    from ball_balance.tf import quat_to_euler
    from ball_balance.tf.ros import Buffer, TransformListener

    launcher.start(python_cmd("-c", BROADCASTER), name="tf_source")
    buffer = Buffer()
    TransformListener(buffer, graph.node)
    graph.spin_until(lambda: buffer.can_transform("world", "plate"), timeout=30, what="world -> plate")
    msg = buffer.lookup_transform("world", "plate")
    assert (msg.header.frame_id, msg.child_frame_id) == ("world", "plate")
    t = msg.transform.translation
    assert (t.x, t.y, t.z) == pytest.approx((0.5, 0.0, 1.1))
    q = msg.transform.rotation
    assert quat_to_euler((q.x, q.y, q.z, q.w))[2] == pytest.approx(math.pi / 2)
    assert msg.header.stamp.sec > 0  # latest common time of the dynamic edge
    # the late-joining listener got both static transforms from one latched message
    assert buffer.core.parent_of("tool") == "base" and buffer.core.parent_of("base") == "world"


def test_tf_echo_and_latched_tf_static_and_one_line_for_a_missing_frame(launcher, ros_domain):
    launcher.start(python_cmd("-c", BROADCASTER), name="tf_source")
    echo = launcher.run([executable("ros2py"), "tf", "echo", "world", "tool", "--count", "1",
                         "--timeout", "20"], timeout=40)
    assert echo.returncode == 0, echo.stderr
    assert "- Translation: [0.500, 0.000, 1.000]" in echo.stdout
    latched = launcher.run([executable("ros2py"), "topic", "echo", "/tf_static", "--once"], timeout=40)
    assert "  child_frame_id: base\n" in latched.stdout and "  child_frame_id: tool\n" in latched.stdout
    missing = launcher.run([executable("ros2py"), "tf", "echo", "world", "no_such_frame", "--count", "1",
                            "--timeout", "3"], timeout=40)
    assert missing.returncode == 1 and missing.stdout == ""
    (line,) = missing.stderr.strip().splitlines()
    assert "[no_such_frame]" in line and "does not exist" in line


def test_listener_with_its_own_thread_serves_lookups_that_wait(launcher, graph):
    from ball_balance.tf.ros import Buffer, TransformListener

    launcher.start(python_cmd("-c", BROADCASTER), name="tf_source")
    buffer = Buffer()
    listener = TransformListener(buffer, graph.node, spin_thread=True)
    try:
        msg = buffer.lookup_transform("base", "plate", timeout_s=30.0)  # nobody spins graph.node
        assert msg.transform.translation.x == pytest.approx(0.5)
        assert msg.transform.translation.z == pytest.approx(0.1)
    finally:
        listener.unregister()
