"""pal_statistics-style registries: `<prefix>/{full,names,values}` with pal_statistics_msgs.

A registry is a list of (name, getter). `publish()` (a timer in the executor, never the
loop) publishes `names` only when the list of names changed (transient local, so late
subscribers get the current list), and `full`/`values` only when someone subscribes; with
no subscribers it costs three subscription-count checks. The messages are allocated once
per names version; each publish only refills their value arrays.
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
        self._getters: List[Callable[[], float]] = []
        self._full = Statistics()
        self._values = StatisticsValues()
        self.published_values = 0

    def set_entries(self, entries: List[Entry]) -> None:
        """Install a new list of entries; publishes /names when the names differ."""
        names = [n for n, _ in entries]
        self._getters = [g for _, g in entries]
        if names == self._names and self.names_version:
            return
        self._names = names
        self.names_version += 1
        self._full = Statistics(statistics=[Statistic(name=n, value=0.0) for n in names])
        self._values = StatisticsValues(values=[0.0] * len(names), names_version=self.names_version)
        msg = StatisticsNames(names=names, names_version=self.names_version)
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.pub_names.publish(msg)

    def publish(self) -> None:
        want_full = self.pub_full.get_subscription_count() > 0
        want_values = self.pub_values.get_subscription_count() > 0
        if not (want_full or want_values):
            return
        stamp = self.node.get_clock().now().to_msg()
        values = self._values.values
        for i, getter in enumerate(self._getters):
            try:
                values[i] = float(getter())
            except Exception:  # noqa: BLE001 - an entry that vanished mid-read
                values[i] = float("nan")
        if want_values:
            self._values.header.stamp = stamp
            self.pub_values.publish(self._values)
            self.published_values += 1
        if want_full:
            for statistic, value in zip(self._full.statistics, values):
                statistic.value = value
            self._full.header.stamp = stamp
            self.pub_full.publish(self._full)
