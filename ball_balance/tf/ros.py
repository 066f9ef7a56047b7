"""The thin rclpy side of TF: a Buffer with ROS types, a listener and the broadcasters.

QoS as tf2_ros uses it:
- /tf: reliable, volatile, keep last 100 (broadcaster and listener);
- /tf_static: reliable, transient local, keep last 1 for the broadcaster (which republishes
  every static transform it ever sent in one TFMessage), keep last 100 for the listener.

    from ball_balance.tf.ros import Buffer, TransformListener, TransformBroadcaster
    buffer = Buffer()
    listener = TransformListener(buffer, node)
    t = buffer.lookup_transform("world", "plate", timeout_s=1.0)   # TransformStamped
"""
from __future__ import annotations

import math
import os
import threading
from typing import Iterable, List, Optional, Union

from builtin_interfaces.msg import Time as TimeMsg
from geometry_msgs.msg import TransformStamped
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

from ball_balance.tf.buffer import NS, BufferCore
from ball_balance.tf.transform import Transform

TF_TOPIC = "/tf"
TF_STATIC_TOPIC = "/tf_static"

DYNAMIC_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                         reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
STATIC_BROADCASTER_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                                    reliability=ReliabilityPolicy.RELIABLE,
                                    durability=DurabilityPolicy.TRANSIENT_LOCAL)
STATIC_LISTENER_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                                 reliability=ReliabilityPolicy.RELIABLE,
                                 durability=DurabilityPolicy.TRANSIENT_LOCAL)


def stamp_to_ns(stamp) -> int:
    """builtin_interfaces/Time, rclpy.time.Time, int nanoseconds or None (latest) -> ns."""
    if stamp is None:
        return 0
    if isinstance(stamp, int):
        return stamp
    if hasattr(stamp, "nanoseconds"):
        return int(stamp.nanoseconds)
    return int(stamp.sec) * NS + int(stamp.nanosec)


def ns_to_stamp(stamp_ns: int) -> TimeMsg:
    return TimeMsg(sec=stamp_ns // NS, nanosec=stamp_ns % NS)


def msg_to_transform(msg: TransformStamped) -> Transform:
    """geometry_msgs/TransformStamped -> Transform (ValueError when not finite/normalizable)."""
    t, q = msg.transform.translation, msg.transform.rotation
    return Transform.from_values((t.x, t.y, t.z), (q.x, q.y, q.z, q.w))


def transform_to_msg(transform: Transform, parent: str, child: str, stamp=None) -> TransformStamped:
    """Transform T_parent_child -> geometry_msgs/TransformStamped."""
    msg = TransformStamped()
    msg.header.frame_id, msg.child_frame_id = parent, child
    msg.header.stamp = ns_to_stamp(stamp_to_ns(stamp))
    tr, rot = msg.transform.translation, msg.transform.rotation
    tr.x, tr.y, tr.z = transform.translation
    rot.x, rot.y, rot.z, rot.w = transform.rotation
    return msg


class Buffer:
    """tf2_ros.Buffer-like: BufferCore with TransformStamped in and out.

    `core` is the pure BufferCore (for callers that want Transform objects and ns times).
    """

    def __init__(self, cache_time_s: float = 10.0):
        self.core = BufferCore(cache_time_s)

    def set_transform(self, msg: TransformStamped, authority: str = "") -> None:
        self.core.set_transform(msg.header.frame_id, msg.child_frame_id,
                                stamp_to_ns(msg.header.stamp), msg_to_transform(msg))

    def set_transform_static(self, msg: TransformStamped, authority: str = "") -> None:
        self.core.set_transform(msg.header.frame_id, msg.child_frame_id,
                                stamp_to_ns(msg.header.stamp), msg_to_transform(msg), static=True)

    def lookup_transform(self, target_frame: str, source_frame: str, time=None,
                         timeout_s: float = 0.0) -> TransformStamped:
        """The pose of source_frame in target_frame at `time` (None/0: latest available).

        Waits up to timeout_s for the data; raises a TransformException naming the frames.
        """
        transform, stamp_ns = self.core.wait_for_transform(
            target_frame, source_frame, stamp_to_ns(time), timeout_s)
        return transform_to_msg(transform, target_frame, source_frame, stamp_ns)

    def lookup_transform_full(self, target_frame: str, target_time, source_frame: str, source_time,
                              fixed_frame: str) -> TransformStamped:
        """source_frame at source_time in target_frame at target_time, via fixed_frame."""
        target_ns = stamp_to_ns(target_time)
        transform = self.core.lookup_transform_full(target_frame, target_ns, source_frame,
                                                    stamp_to_ns(source_time), fixed_frame)
        return transform_to_msg(transform, target_frame, source_frame, target_ns)

    def can_transform(self, target_frame: str, source_frame: str, time=None) -> bool:
        return self.core.can_transform(target_frame, source_frame, stamp_to_ns(time))

    def all_frames(self) -> List[str]:
        return self.core.all_frames()


class TransformListener:
    """Fills a Buffer from /tf and /tf_static.

    spin_thread=True spins the subscriptions on a private node in a background thread (so
    lookups with a timeout work while the caller's node is blocked); otherwise they are
    served by whatever executor spins `node`.
    """

    def __init__(self, buffer: Buffer, node, spin_thread: bool = False,
                 qos: QoSProfile = DYNAMIC_QOS, static_qos: QoSProfile = STATIC_LISTENER_QOS):
        self.buffer, self._thread, self._executor, self._own_node = buffer, None, None, None
        self._logger = node.get_logger()
        if spin_thread:
            import rclpy
            from rclpy.executors import SingleThreadedExecutor

            self._own_node = rclpy.create_node(f"_tf_listener_{os.getpid()}_{id(self):x}",
                                               context=node.context, start_parameter_services=False)
            node = self._own_node
        self._subscriptions = [
            node.create_subscription(TFMessage, TF_TOPIC, self._on_tf, qos),
            node.create_subscription(TFMessage, TF_STATIC_TOPIC, self._on_tf_static, static_qos),
        ]
        if spin_thread:
            self._executor = SingleThreadedExecutor(context=node.context)
            self._executor.add_node(node)
            self._thread = threading.Thread(target=self._spin, daemon=True, name="tf_listener")
            self._thread.start()

    def _spin(self) -> None:
        try:
            self._executor.spin()
        except Exception:  # noqa: BLE001 - context shut down under us
            pass

    def _on_tf(self, msg: TFMessage) -> None:
        self._store(msg, static=False)

    def _on_tf_static(self, msg: TFMessage) -> None:
        self._store(msg, static=True)

    def _store(self, msg: TFMessage, static: bool) -> None:
        for t in msg.transforms:
            try:
                self.buffer.core.set_transform(t.header.frame_id, t.child_frame_id,
                                               stamp_to_ns(t.header.stamp), msg_to_transform(t), static)
            except Exception as error:  # noqa: BLE001 - bad data from the wire: drop, keep going
                self._logger.warn(f"dropped transform [{t.header.frame_id}] -> [{t.child_frame_id}]: {error}",
                                  throttle_duration_sec=5.0)

    def unregister(self) -> None:
        if self._executor is not None:
            self._executor.shutdown(timeout_sec=1.0)
        if self._own_node is not None:
            self._own_node.destroy_node()


def _as_list(transforms: Union[TransformStamped, Iterable[TransformStamped]]) -> List[TransformStamped]:
    return [transforms] if isinstance(transforms, TransformStamped) else list(transforms)


def _check_finite(transforms: List[TransformStamped]) -> None:
    for t in transforms:
        tr, q = t.transform.translation, t.transform.rotation
        if not all(math.isfinite(v) for v in (tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w)):
            raise ValueError(f"transform [{t.header.frame_id}] -> [{t.child_frame_id}] is not finite")


class TransformBroadcaster:
    """Publishes dynamic transforms on /tf (reliable, volatile, depth 100)."""

    def __init__(self, node, qos: Optional[QoSProfile] = None):
        self._publisher = node.create_publisher(TFMessage, TF_TOPIC, qos or DYNAMIC_QOS)

    def send_transform(self, transforms) -> None:
        transforms = _as_list(transforms)
        _check_finite(transforms)
        self._publisher.publish(TFMessage(transforms=transforms))


class StaticTransformBroadcaster:
    """Latches static transforms on /tf_static (transient local, depth 1).

    As tf2_ros does: it keeps every transform sent so far (one per child frame, the last
    one wins) and republishes all of them, so a late subscriber gets the whole set.
    """

    def __init__(self, node, qos: Optional[QoSProfile] = None):
        self._publisher = node.create_publisher(TFMessage, TF_STATIC_TOPIC, qos or STATIC_BROADCASTER_QOS)
        self._by_child = {}

    def send_transform(self, transforms) -> None:
        transforms = _as_list(transforms)
        _check_finite(transforms)
        for t in transforms:
            self._by_child[t.child_frame_id] = t
        self._publisher.publish(TFMessage(transforms=list(self._by_child.values())))
