"""Statistics (names, values, first sample), publishing rules, and diagnostics levels."""
import math
import threading
import time

import numpy as np
import pytest
from cm_helpers import JOINTS, make_manager, run, spawn

from controller_manager_py.manager.diagnostics import ERROR, OK, THRESHOLD_PARAMS, WARN, roll_up
from controller_manager_py.manager.introspection import introspection_entries, statistics_entries
from controller_manager_py.manager.statistics import PeriodicityStats, Stats

THRESHOLDS = {p.name: p.default for p in THRESHOLD_PARAMS}


def test_running_statistics_match_the_textbook_formulas():
    samples = [3.0, 1.0, 4.0, 1.0, 5.0, 9.0, 2.0, 6.0]
    s = Stats()
    for x in samples:
        s.add(x)
    mean = sum(samples) / len(samples)
    assert (s.max, s.min, s.sample_count, s.current_value) == (9.0, 1.0, 8, 6.0)
    assert s.average == pytest.approx(mean, abs=1e-12)
    assert s.standard_deviation == pytest.approx(math.sqrt(sum((x - mean) ** 2 for x in samples) / 8), abs=1e-12)


def test_first_run_gives_no_periodicity_sample():
    p = PeriodicityStats()
    p.add(10.0, 10.0001)
    assert p.periodicity.sample_count == 0 and p.execution_time.sample_count == 1
    p.add(10.002, 10.0021)
    assert p.periodicity.current_value == pytest.approx(500.0)


def test_statistics_and_introspection_use_ros2_control_names():
    cm = make_manager()
    spawn(cm, "fwd", "position_controllers/JointGroupPositionController", {"joints": JOINTS})
    run(cm, 10)
    stats = dict(statistics_entries(cm))
    for name in ("fwd.stats/execution_time/average", "fwd.stats/periodicity/standard_deviation",
                 "mock_ur.stats/read_cycle/execution_time/max", "mock_ur.stats/write_cycle/periodicity/sample_count",
                 "controller_manager.stats/periodicity/min", "controller_manager.stats/execution_time/max"):
        assert name in stats, name
    jazzy = [f"controller_manager.{x}_time" for x in ("update", "read", "write", "total", "switch",
                                                       "switch_chained_mode", "switch_perform_mode",
                                                       "deactivation", "activation")]
    assert [n for n in stats if n in jazzy] == jazzy
    assert stats["controller_manager.total_time"]() > 0.0
    assert stats["fwd.stats/execution_time/sample_count"]() == 10
    assert stats["fwd.stats/periodicity/sample_count"]() == 9
    intro = dict(introspection_entries(cm))
    assert intro["state_interface.elbow_joint/position"]() == pytest.approx(math.pi / 2)
    assert intro["command_interface.elbow_joint/position.is_limited"]() == 0.0
    assert "state_interface.speed_scaling/speed_scaling_factor" in intro
    assert intro["fwd.refused_commands"]() == 0.0  # registered by the controller in on_configure


def _controller_with(cm, rate_hz, exec_us, n=50):
    spec = cm.controllers["c"]
    spec.stats.reset()
    t = 0.0
    for _ in range(n):
        spec.stats.add(t, t + exec_us * 1e-6)
        t += 1.0 / rate_hz
    return spec


@pytest.mark.parametrize("rate_hz, exec_us, level", [
    (500.0, 200.0, OK),
    (493.0, 200.0, WARN),  # periodicity mean error 7 Hz > 5
    (488.0, 200.0, ERROR),  # 12 Hz > 10
    (500.0, 1500.0, WARN),  # execution time mean 1500 us > 1000
    (500.0, 2500.0, ERROR),
])
def test_controller_diagnostics_cross_the_default_thresholds(rate_hz, exec_us, level):
    cm = make_manager(rate=500)
    spawn(cm, "c", "cm_helpers:CountingController")
    _controller_with(cm, rate_hz, exec_us)
    controllers, hardware, manager = roll_up(cm, THRESHOLDS)
    assert controllers.level == level, controllers.message
    assert controllers.name == "Controllers Activity"


def test_manager_diagnostics_report_loop_periodicity():
    cm = make_manager(rate=500)
    t = 0.0
    for k in range(100):
        cm.loop_stats.add(t, t + 1e-4)
        t += 1 / 500 if k % 2 else 1 / 250  # alternating 2 ms / 4 ms: large std dev
    *_, manager = roll_up(cm, THRESHOLDS)
    assert manager.level == ERROR and "periodicity" in manager.message
    assert ("update loop longest period (ms)", "4.000") in manager.values


class FakePublisher:
    def __init__(self):
        self.subscribers, self.sent = 0, []

    def get_subscription_count(self):
        return self.subscribers

    def publish(self, msg):
        self.sent.append(msg)


class FakeNode:
    def __init__(self):
        self.publishers = {}

    def create_publisher(self, msg_type, topic, qos):
        self.publishers[topic.rsplit("/", 1)[-1]] = FakePublisher()
        return self.publishers[topic.rsplit("/", 1)[-1]]

    def get_clock(self):
        from builtin_interfaces.msg import Time

        class Clock:
            def now(self):
                class Now:
                    def to_msg(self):
                        return Time()
                return Now()
        return Clock()


def test_names_only_on_change_values_only_with_subscribers():
    from controller_manager_py.ros.statistics_publisher import StatisticsRegistry

    node = FakeNode()
    registry = StatisticsRegistry(node, "~/statistics")
    value = [1.0]
    registry.set_entries([("a", lambda: value[0]), ("b", lambda: 2.0)])
    registry.set_entries([("a", lambda: value[0]), ("b", lambda: 2.0)])  # same names: nothing sent
    assert len(node.publishers["names"].sent) == 1
    registry.publish()
    assert node.publishers["values"].sent == [] and node.publishers["full"].sent == []
    node.publishers["values"].subscribers = 1
    value[0] = 7.0
    registry.publish()
    (msg,) = node.publishers["values"].sent
    assert list(msg.values) == [7.0, 2.0] and msg.names_version == 1
    assert node.publishers["full"].sent == []
    registry.set_entries([("a", lambda: 1.0)])
    assert node.publishers["names"].sent[-1].names_version == 2


def test_the_cycle_that_applies_a_switch_reports_its_switch_times_and_the_next_reports_zero():
    cm = make_manager()
    spawn(cm, "fwd", "position_controllers/JointGroupPositionController", {"joints": JOINTS}, activate=False)
    cm.loop_running = True  # cycles are driven by hand
    thread = threading.Thread(target=cm.switch_controller, args=(["fwd"], [], 2))
    thread.start()
    deadline = time.monotonic() + 10
    while cm._pending is None and time.monotonic() < deadline:
        time.sleep(0.001)
    run(cm, 1)
    thread.join(10)
    times = cm.execution_time
    assert times.switch_time > 0 and times.activation_time > 0 and times.switch_time >= times.activation_time
    run(cm, 1)
    assert times.switch_time == 0.0 and times.total_time > 0.0


def test_refused_and_limited_commands_turn_diagnostics_warn_with_counts_then_ok_again():
    cm = make_manager(rate=500)
    fwd = spawn(cm, "fwd", "position_controllers/JointGroupPositionController", {"joints": JOINTS})
    counts = {}
    controllers, hardware, _ = roll_up(cm, THRESHOLDS, counts)
    assert controllers.level == OK and hardware.level == OK
    fwd.slot.offer([float("nan")] * 6)  # refused at the edge
    fwd.slot.offer([0.0, -1.57, 50.0, -1.57, 1.57, 0.0])  # accepted, then limited before write
    run(cm, 3)
    for stats in cm.all_stats():  # synthetic cycles: their timing is not what is tested here
        stats.reset()
    controllers, hardware, _ = roll_up(cm, THRESHOLDS, counts)
    assert controllers.level == WARN and "fwd: 1 refused commands since the last report (1 in all)" \
        in controllers.message
    assert hardware.level == WARN and "mock_ur: 3 limited commands" in hardware.message
    assert ("fwd refused commands", "1") in controllers.values
    fwd.slot.reset()
    controllers, hardware, _ = roll_up(cm, THRESHOLDS, counts)
    assert controllers.level == OK and hardware.level == OK  # nothing new since the last report


def test_values_registered_in_diagnostics_are_listed_and_never_graded():
    cm = make_manager(rate=500)
    fwd = spawn(cm, "fwd", "position_controllers/JointGroupPositionController", {"joints": JOINTS})
    fwd.register_introspection("level_offset_deg", lambda: 2.0, in_diagnostics=True)
    fwd.register_introspection("internal_gain", lambda: 5.0)
    controllers, _, _ = roll_up(cm, THRESHOLDS, {})
    assert ("fwd level_offset_deg", "2.0000") in controllers.values
    assert not any("internal_gain" in key for key, _ in controllers.values)
    assert controllers.level == OK


class CountedRegistry:
    """Stands in for a statistics registry: the cycles it was published in, each taking 1 ms."""

    def __init__(self, cycle):
        self.cycle, self.published = cycle, []

    def publish(self):
        time.sleep(0.001)
        self.published.append(self.cycle[0])


def test_statistics_wait_for_slack_but_never_more_than_a_publishing_period():
    from types import SimpleNamespace

    from controller_manager_py.ros.node import ControllerManagerNode

    cycle = [0]
    node = SimpleNamespace(_cycles_since_due=0, _publish_every=25, _pending_publish=[], _publish_cost={},
                           statistics=CountedRegistry(cycle), introspection=CountedRegistry(cycle))
    for cycle[0] in range(100):          # a second to spare after each cycle: every 25 cycles
        ControllerManagerNode.on_loop_idle(node, 1.0)
    assert node.statistics.published == [24, 49, 74, 99]
    for cycle[0] in range(100, 400):     # no slack at all (a machine too slow for the rate)
        ControllerManagerNode.on_loop_idle(node, 0.0)
    # each publication a period late, never later: the heartbeat goes on at about the same rate
    gaps = np.diff(node.statistics.published)
    assert len(node.statistics.published) >= 4 + 300 // 30 and gaps.max() <= 2 * 25 + 1
    assert np.diff(node.introspection.published).max() <= 2 * 25 + 1
