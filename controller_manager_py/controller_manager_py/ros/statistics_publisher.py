"""pal_statistics-style registries: `<prefix>/{full,names,values}` with pal_statistics_msgs.

A registry is a list of (name, getter). `set_entries()` (executor thread, when the
manager's set of controllers/components changed) publishes `names` only when the names
changed (transient local, so late subscribers get the current list) and swaps in new
preallocated messages in one assignment. `publish()` fills and sends `full`/`values`
only when someone subscribes; with no subscribers it costs two subscription-count
checks. The node calls publish() from the loop's idle time (after a cycle, only when
half a period is left), so the interpreter time of building `full` never delays a cycle.
"""
from __future__ import annotations

from typing import Callable, List, Tuple

from pal_statistics_msgs.msg import Statistic, Statistics, StatisticsNames, StatisticsValues
from rclpy.qos import DurabilityPolicy, QoSProfile

Entry = Tuple[str, Callable[[], float]]


class StatisticsRegistry:
    def __init__(self, node, prefix: str):
        self.node = node
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.pub_full = node.create_publisher(Statistics, f"{prefix}/full", 10)
        self.pub_names = node.create_publisher(StatisticsNames, f"{prefix}/names", latched)
        self.pub_values = node.create_publisher(StatisticsValues, f"{prefix}/values", 10)
        self.names_version = 0
        self._names: List[str] = []
        # (getters, full message, values message), replaced as a whole by set_entries
        self._current = ([], Statistics(), StatisticsValues())
        self.published_values = 0

    def set_entries(self, entries: List[Entry]) -> None:
        """Install a new list of entries; publishes /names when the names differ."""
        names = [n for n, _ in entries]
        getters = [g for _, g in entries]
        if names == self._names and self.names_version:
            self._current = (getters, self._current[1], self._current[2])
            return
        self._names = names
        self.names_version += 1
        self._current = (getters, Statistics(statistics=[Statistic(name=n, value=0.0) for n in names]),
                         StatisticsValues(values=[0.0] * len(names), names_version=self.names_version))
        msg = StatisticsNames(names=names, names_version=self.names_version)
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.pub_names.publish(msg)

    def publish(self) -> None:
        want_full = self.pub_full.get_subscription_count() > 0
        want_values = self.pub_values.get_subscription_count() > 0
        if not (want_full or want_values):
            return
        getters, full, values_msg = self._current
        stamp = self.node.get_clock().now().to_msg()
        values = values_msg.values
        for i, getter in enumerate(getters):
            try:
                values[i] = float(getter())
            except Exception:  # noqa: BLE001 - an entry that vanished mid-read
                values[i] = float("nan")
        if want_values:
            values_msg.header.stamp = stamp
            self.pub_values.publish(values_msg)
            self.published_values += 1
        if want_full:
            for statistic, value in zip(full.statistics, values):
                statistic.value = value
            full.header.stamp = stamp
            self.pub_full.publish(full)
