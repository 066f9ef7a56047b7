"""The trajectory controller's ~/controller_state timer and its action monitor run only while
the controller is active (the monitor also while a goal still waits for its outcome): an
inactive controller's timers stop at their next tick instead of waking the executor for
nothing, and the controller's first update after an activation starts them again."""
from types import SimpleNamespace

import pytest

from controller_manager_py.controllers.follow_joint_trajectory import TrajectoryRosInterface


class Timer:
    """rclpy.timer.Timer's cancel / reset / is_canceled."""

    def __init__(self):
        self.canceled = False

    def cancel(self):
        self.canceled = True

    def reset(self):
        self.canceled = False

    def is_canceled(self):
        return self.canceled


class Publisher:
    def __init__(self):
        self.sent = 0

    def publish(self, msg):
        self.sent += 1


def interface(active: bool) -> TrajectoryRosInterface:
    """The ROS side with its timers and publisher replaced, around a controller stand-in."""
    ros = TrajectoryRosInterface.__new__(TrajectoryRosInterface)
    ros.c = SimpleNamespace(active=active, _snapshot=None, _run=None)
    ros.state_timer, ros.monitor, ros.state_pub, ros._runs = Timer(), Timer(), Publisher(), {}
    return ros


def test_an_inactive_controller_stops_its_timers_and_activation_restarts_them():
    ros = interface(active=False)
    ros.publish_state()
    ros.on_monitor()
    assert ros.state_timer.is_canceled() and ros.monitor.is_canceled() and ros.state_pub.sent == 0
    ros.c.active = True
    ros.on_activation()                             # (the guard condition's callback)
    assert not ros.state_timer.is_canceled() and not ros.monitor.is_canceled()
    ros.on_monitor()
    assert not ros.monitor.is_canceled()            # active: keeps running


def test_the_monitor_runs_on_while_a_goal_waits_for_its_outcome():
    ros = interface(active=False)
    run = SimpleNamespace(outcome=None)
    handle = SimpleNamespace(is_cancel_requested=False)
    ros._runs[b"goal"] = (handle, run, None)
    ros.on_monitor()
    assert not ros.monitor.is_canceled()


class UpdateStopped(Exception):
    pass


def stop_update():
    raise UpdateStopped   # the rest of update() is not what this test is about


def test_the_first_update_after_activation_announces_it_once():
    from controller_manager_py.controllers.joint_trajectory import JointTrajectoryController
    announced = []
    c = JointTrajectoryController.__new__(JointTrajectoryController)
    c.ros = SimpleNamespace(announce_activation=lambda: announced.append(1))
    c._announce_activation, c._read_state = True, stop_update
    for _ in range(2):
        with pytest.raises(UpdateStopped):
            c.update(0.0, 0.002)
    assert announced == [1]


def test_an_active_controller_keeps_its_state_timer_before_its_first_snapshot():
    ros = interface(active=True)
    ros.publish_state()                             # nothing to publish yet
    assert not ros.state_timer.is_canceled() and ros.state_pub.sent == 0
