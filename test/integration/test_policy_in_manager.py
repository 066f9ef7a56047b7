"""The ball balanced inside the simulated arm's controller manager (scripts/sim_policy_in_manager.sh):
the learned policy's controller replaces forward_position_controller, and its joint commands
tilt the plate so that the ball comes to the centre."""
import math
import time

import numpy as np
import pytest
from ball_tracker_msgs.msg import BallState
from geometry_msgs.msg import Vector3Stamped
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState

from ball_balance.robot import HOME_POSITIONS_RAD, JOINT_NAMES
from harness import ROOT

pytestmark = [pytest.mark.integration, pytest.mark.slow]


def wait_for(condition, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"timed out after {timeout:.0f} s waiting for {what}"
        time.sleep(0.2)


def test_the_policy_controller_in_the_manager_brings_the_ball_to_the_centre(launcher, graph):
    script = launcher.start([str(ROOT / "scripts" / "sim_policy_in_manager.sh"), "--truth-fed",
                             "--ball", "0.06", "-0.04"], name="sim_policy_in_manager")
    # generous: the simulated arm and the model load slowly on a busy machine
    wait_for(lambda: "ball_balance_controller active" in script.output() or not script.running, 240,
             "the controller to be active in the manager")
    assert script.running, script.output()
    # the simulation, paused until the graph is up, runs once the controller has taken over
    wait_for(lambda: "simulation resumed" in script.output() or not script.running, 120, "the simulation to resume")
    assert script.running, script.output()
    # the controller commands the joints: the plate leaves its level home pose
    home = np.array(HOME_POSITIONS_RAD)

    def tilted(msg: JointState) -> bool:
        index = {n: i for i, n in enumerate(msg.name)}
        q = np.array([msg.position[index[n]] for n in JOINT_NAMES])
        return bool(np.max(np.abs(q - home)) > 0.002)

    graph.collect(JointState, "/joint_states", timeout=120, predicate=tilted)
    # its tilt reaches the tracker's feed-forward topic
    graph.collect(Vector3Stamped, "/plate_cmd", timeout=60,
                  predicate=lambda m: m.header.frame_id == "plate_center" and m.vector.x != 0.0)
    # the ball comes to within 25 mm of the centre (released ~72 mm off it) and is on the plate
    graph.collect(BallState, "/sim/ball_truth", timeout=180, qos=qos_profile_sensor_data,
                  predicate=lambda m: math.hypot(m.x, m.y) < 0.025)
    assert script.running, script.output()
