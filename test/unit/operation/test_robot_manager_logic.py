"""The robot manager's plain logic: the lifecycle table, the watchdogs, the levelling path."""
import pytest

from ball_balance.operation import lifecycle as lc
from ball_balance.operation.levelling import SMOOTHSTEP_PEAK, levelling_duration, levelling_path, smoothstep
from ball_balance.operation.watchdog import (
    CAMERA_LOST,
    CONTROLLER_STOPPED,
    HARDWARE_ERROR,
    MANAGER_STALLED,
    Watchdog,
    WatchdogLimits,
)


def test_each_state_offers_the_transitions_ros2_lifecycle_lists():
    assert [t.describe() for t in lc.available(lc.UNCONFIGURED)] == ["configure [1]", "shutdown [5]"]
    assert [t.describe() for t in lc.available(lc.INACTIVE)] == ["cleanup [2]", "activate [3]", "shutdown [6]"]
    assert [t.describe() for t in lc.available(lc.ACTIVE)] == ["deactivate [4]", "shutdown [7]"]
    assert lc.available(lc.FINALIZED) == []


def test_a_transition_is_found_by_label_or_id_and_refused_with_what_is_available():
    assert lc.resolve(lc.ACTIVE, label="shutdown").id == 7
    assert lc.resolve(lc.INACTIVE, transition_id=3).label == "activate"
    with pytest.raises(lc.LifecycleError, match=r"'activate' is not available in state unconfigured.*configure \[1\]"):
        lc.resolve(lc.UNCONFIGURED, label="activate")


def test_the_outcome_follows_the_hook_result():
    configure = lc.resolve(lc.UNCONFIGURED, label="configure")
    assert lc.outcome(configure, lc.SUCCESS) == lc.INACTIVE
    assert lc.outcome(configure, lc.FAILURE) == lc.UNCONFIGURED
    assert lc.outcome(configure, lc.ERROR, lc.SUCCESS) == lc.UNCONFIGURED
    assert lc.outcome(configure, lc.ERROR, lc.FAILURE) == lc.FINALIZED


def _watchdog(**state):
    dog = Watchdog(WatchdogLimits(manager_timeout_s=2.0, camera_timeout_s=1.0))
    dog.last_heartbeat_s, dog.last_frame_s = 10.0, 10.0
    dog.hardware = {"arm": "active"}
    for key, value in state.items():
        setattr(dog, key, value)
    return dog


def test_a_quiet_graph_is_fine():
    assert _watchdog(ball_on_plate=True).check(10.5) is None


def test_a_component_that_left_active_is_a_hardware_error():
    source, reason = _watchdog(hardware={"arm": "unconfigured"}).check(10.1)
    assert source == HARDWARE_ERROR and "'arm' is unconfigured" in reason


def test_a_balancing_controller_that_left_active_is_stopped_once_it_had_been_active():
    dog = _watchdog()
    dog.forget_controllers()
    dog.watch_controllers({"balance": "inactive"})   # the state from before the activation's switch
    assert dog.check(10.1) is None
    dog.watch_controllers({"balance": "active"})
    assert dog.check(10.1) is None
    dog.watch_controllers({"balance": "inactive"})   # someone switched it off
    source, reason = dog.check(10.1)
    assert source == CONTROLLER_STOPPED and "'balance' is inactive" in reason
    dog.watch_controllers({})                          # unloaded
    assert "'balance' is unloaded" in dog.check(10.1)[1]
    dog.forget_controllers()                          # the next activation starts afresh
    assert dog.check(10.1) is None


def test_no_heartbeat_for_longer_than_the_limit_is_a_stalled_manager():
    assert _watchdog().check(11.9) is None
    source, reason = _watchdog().check(12.5)
    assert source == MANAGER_STALLED and "2.5 s" in reason


def test_the_camera_counts_as_lost_only_with_the_ball_on_the_plate():
    assert _watchdog(ball_on_plate=False, last_heartbeat_s=11.5).check(11.5) is None
    source, _ = _watchdog(ball_on_plate=True, last_heartbeat_s=11.5).check(11.5)
    assert source == CAMERA_LOST
    assert _watchdog(ball_on_plate=True, last_heartbeat_s=11.5, last_frame_s=None).check(11.5) is None


def test_arming_restarts_the_timeouts():
    dog = _watchdog()
    dog.arm(20.0)
    assert dog.check(21.0) is None


def test_the_levelling_path_starts_and_ends_at_rest_within_the_speed_limit():
    q0, q1 = [0.0, 0.1, -0.2], [0.0, 0.0, 0.0]
    duration = levelling_duration(q0, q1, max_speed_rad_s=0.05, min_duration_s=1.0)
    assert duration == pytest.approx(SMOOTHSTEP_PEAK * 0.2 / 0.05)
    path = levelling_path(q0, q1, duration, 200)
    assert path[-1][0] == pytest.approx(duration) and path[-1][1] == pytest.approx(q1)
    speeds = [abs(b[1][2] - a[1][2]) / (b[0] - a[0]) for a, b in zip(path, path[1:])]
    assert max(speeds) <= 0.05 * 1.001
    assert smoothstep(0.0) == 0.0 and smoothstep(1.0) == 1.0 and smoothstep(0.5) == pytest.approx(0.5)
    assert levelling_duration(q0, q1, max_speed_rad_s=10.0, min_duration_s=1.0) == 1.0
