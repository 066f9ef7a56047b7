"""The trajectory controller's ~/controller_state timer runs only while the controller is
active: an inactive controller's timer stops at its next tick instead of waking the executor
for nothing, and the action monitor starts it again after activation."""
from types import SimpleNamespace

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
    ros.state_timer, ros.state_pub, ros._runs = Timer(), Publisher(), {}
    return ros


def test_an_inactive_controller_stops_its_state_timer_and_activation_restarts_it():
    ros = interface(active=False)
    ros.publish_state()
    assert ros.state_timer.is_canceled() and ros.state_pub.sent == 0
    ros.on_monitor()
    assert ros.state_timer.is_canceled()           # still inactive: stays stopped
    ros.c.active = True
    ros.on_monitor()
    assert not ros.state_timer.is_canceled()


def test_an_active_controller_keeps_its_state_timer_before_its_first_snapshot():
    ros = interface(active=True)
    ros.publish_state()                             # nothing to publish yet
    assert not ros.state_timer.is_canceled() and ros.state_pub.sent == 0
