"""The rclpy side of TF without DDS: message conversion, tf2 QoS, static accumulation."""
import pytest
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

from ball_balance.tf import Transform, TransformException, quat_from_euler
from ball_balance.tf.ros import (
    TF_STATIC_TOPIC,
    TF_TOPIC,
    Buffer,
    StaticTransformBroadcaster,
    TransformBroadcaster,
    msg_to_transform,
    transform_to_msg,
)


class FakePublisher:
    def __init__(self):
        self.sent = []

    def publish(self, msg):
        self.sent.append(msg)


class FakeNode:
    def __init__(self):
        self.publishers = {}

    def create_publisher(self, msg_type, topic, qos):
        self.publishers[topic] = (qos, FakePublisher())
        return self.publishers[topic][1]


def test_messages_round_trip_with_stamp():
    T = Transform((1.0, 2.0, 3.0), quat_from_euler(0.1, 0.2, 0.3))
    msg = transform_to_msg(T, "world", "plate", 1_500_000_000)
    assert (msg.header.frame_id, msg.child_frame_id) == ("world", "plate")
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1, 500_000_000)
    assert msg_to_transform(msg).is_close(T)


def test_broadcasters_use_tf2_qos():
    node = FakeNode()
    TransformBroadcaster(node)
    StaticTransformBroadcaster(node)
    dynamic_qos, _ = node.publishers[TF_TOPIC]
    static_qos, _ = node.publishers[TF_STATIC_TOPIC]
    assert (dynamic_qos.depth, dynamic_qos.reliability, dynamic_qos.durability) == (
        100, ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE)
    assert (static_qos.depth, static_qos.reliability, static_qos.durability) == (
        1, ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL)


def test_static_broadcaster_accumulates_and_republishes_everything():
    node = FakeNode()
    static = StaticTransformBroadcaster(node)
    static.send_transform(transform_to_msg(Transform((1.0, 0, 0)), "world", "base"))
    static.send_transform(transform_to_msg(Transform((0, 1.0, 0)), "base", "camera"))
    static.send_transform(transform_to_msg(Transform((2.0, 0, 0)), "world", "base"))  # replaces the first
    last = node.publishers[TF_STATIC_TOPIC][1].sent[-1]
    assert [(t.child_frame_id, t.transform.translation.x) for t in last.transforms] == [("base", 2.0),
                                                                                          ("camera", 0.0)]


def test_buffer_returns_transform_stamped_and_refuses_non_finite_input():
    buffer = Buffer()
    buffer.set_transform_static(transform_to_msg(Transform((0, 0, 1.0)), "world", "base"))
    buffer.set_transform(transform_to_msg(Transform((0.5, 0, 0)), "base", "plate", 2_000_000_000))
    out = buffer.lookup_transform("world", "plate")
    assert (out.transform.translation.x, out.transform.translation.z, out.header.stamp.sec) == (0.5, 1.0, 2)
    full = buffer.lookup_transform_full("plate", 2_000_000_000, "base", 0, "world")
    assert (full.header.frame_id, full.transform.translation.x) == ("plate", -0.5)
    with pytest.raises(TransformException, match=r"\[nowhere\]"):
        buffer.lookup_transform("world", "nowhere", timeout_s=0.2)
    bad = transform_to_msg(Transform(), "world", "x")
    bad.transform.translation.x = float("nan")
    with pytest.raises(ValueError, match="not finite"):
        TransformBroadcaster(FakeNode()).send_transform(bad)
