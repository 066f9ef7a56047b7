"""Joint trajectory controller: spline math, blending, speed scaling, refused trajectories."""
import math

import numpy as np
import pytest
from builtin_interfaces.msg import Duration
from cm_helpers import HOME, JOINTS, make_manager, positions, run, spawn
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from controller_manager_py.controllers.spline import clamped_spline_velocities, hermite

JTC = "joint_trajectory_controller/JointTrajectoryController"


def trajectory(points, joints=JOINTS, velocities=None):
    msg = JointTrajectory(joint_names=list(joints))
    for k, (t, p) in enumerate(points):
        d = Duration(sec=int(t), nanosec=int(round((t % 1) * 1e9)))
        msg.points.append(JointTrajectoryPoint(positions=list(p), time_from_start=d,
                                               velocities=list(velocities[k]) if velocities else []))
    return msg


def offset(delta):
    return [h + delta for h in HOME]


def test_tridiagonal_spline_velocities_match_a_dense_solve():
    t = [0.0, 0.3, 0.7, 1.0, 1.8, 2.0]
    p = [0.0, 1.0, -0.5, 2.0, 1.0, 1.5]
    v = clamped_spline_velocities(t, p, 0.4, 0.0)
    n, h = len(t), np.diff(t)
    A, b = np.zeros((n, n)), np.zeros(n)
    A[0, 0] = A[-1, -1] = 1.0
    b[0], b[-1] = 0.4, 0.0
    for i in range(1, n - 1):
        A[i, i - 1:i + 2] = [h[i], 2 * (h[i - 1] + h[i]), h[i - 1]]
        b[i] = 3 * (h[i] * (p[i] - p[i - 1]) / h[i - 1] + h[i - 1] * (p[i + 1] - p[i]) / h[i])
    assert np.allclose(v, np.linalg.solve(A, b), atol=1e-12)
    # acceleration is continuous at the interior knots
    for i in range(1, n - 1):
        left = hermite(t[i - 1], p[i - 1], v[i - 1], t[i], p[i], v[i], t[i])[2]
        right = hermite(t[i], p[i], v[i], t[i + 1], p[i + 1], v[i + 1], t[i])[2]
        assert left == pytest.approx(right, abs=1e-9)


def test_position_only_waypoints_are_passed_at_their_times_and_held_at_the_end():
    cm = make_manager(rate=100)
    jtc = spawn(cm, "jtc", JTC, {"joints": JOINTS})
    assert jtc.on_trajectory(trajectory([(0.5, offset(0.1)), (1.0, offset(0.2)), (1.5, offset(0.15))]))
    t = run(cm, 51)  # first cycle picks the trajectory up; 50 cycles = 0.5 s of trajectory time
    assert jtc.desired_p == pytest.approx(offset(0.1), abs=1e-9)
    run(cm, 150, start=t)
    assert positions(cm) == pytest.approx(offset(0.15), abs=1e-12)
    assert jtc.desired_v == [0.0] * 6


def test_new_trajectory_blends_from_the_current_state_without_a_jump():
    cm = make_manager(rate=100)
    jtc = spawn(cm, "jtc", JTC, {"joints": JOINTS})
    jtc.on_trajectory(trajectory([(1.0, offset(0.3))]))
    t = run(cm, 40)
    before_p, before_v = list(jtc.desired_p), list(jtc.desired_v)
    assert before_v[0] > 0.1
    jtc.on_trajectory(trajectory([(1.0, offset(-0.2))]))
    t = run(cm, 1, start=t)  # pick-up cycle: same state
    assert jtc.desired_p == pytest.approx(before_p)
    run(cm, 1, start=t)  # one step later: continuous position and velocity
    # p + v dt up to the acceleration term a dt^2 / 2 (a few 1e-4 rad): no jump
    assert jtc.desired_p[0] == pytest.approx(before_p[0] + before_v[0] * 0.01, abs=5e-4)
    assert jtc.desired_v[0] == pytest.approx(before_v[0], abs=0.05)


def test_speed_scaling_slows_trajectory_time():
    cm = make_manager(rate=100)
    jtc = spawn(cm, "jtc", JTC, {"joints": JOINTS,
                                 "speed_scaling_interface_name": "speed_scaling/speed_scaling_factor"})
    cm.rm.state_interfaces["speed_scaling/speed_scaling_factor"].value = 0.5
    jtc.on_trajectory(trajectory([(0.5, offset(0.1))]))
    t = run(cm, 51)
    assert jtc.traj_time == pytest.approx(0.25)
    assert jtc.desired_p[0] < 0.1
    run(cm, 50, start=t)
    assert jtc.desired_p == pytest.approx(offset(0.1))


def test_bad_trajectories_are_refused_and_the_running_one_continues():
    cm = make_manager(rate=100)
    jtc = spawn(cm, "jtc", JTC, {"joints": JOINTS})
    jtc.on_trajectory(trajectory([(1.0, offset(0.2))]))
    t = run(cm, 30)
    assert not jtc.on_trajectory(trajectory([(0.5, offset(0.0))], joints=JOINTS[:5] + ["knee_joint"]))
    assert not jtc.on_trajectory(trajectory([(0.5, offset(0.0)), (0.4, offset(0.1))]))
    assert not jtc.on_trajectory(trajectory([(0.5, [math.nan] * 6)]))
    assert not jtc.on_trajectory(trajectory([(0.5, HOME[:2])], joints=JOINTS[:2]))  # partial not allowed
    assert jtc.refused == 4
    run(cm, 80, start=t)
    assert positions(cm) == pytest.approx(offset(0.2))


def test_waypoint_velocities_are_used_when_given():
    cm = make_manager(rate=100)
    jtc = spawn(cm, "jtc", JTC, {"joints": JOINTS})
    jtc.on_trajectory(trajectory([(0.5, offset(0.1)), (1.0, offset(0.2))], velocities=[[0.2] * 6, [0.0] * 6]))
    run(cm, 51)
    assert jtc.desired_v == pytest.approx([0.2] * 6, abs=1e-6)


def test_ur_scaled_controller_reads_speed_scaling_by_default():
    cm = make_manager(rate=100)
    jtc = spawn(cm, "scaled", "ur_controllers/ScaledJointTrajectoryController", {"joints": JOINTS})
    assert "speed_scaling/speed_scaling_factor" in cm.controllers["scaled"].state_names
    cm.rm.state_interfaces["speed_scaling/speed_scaling_factor"].value = 0.0  # paused on the pendant
    jtc.on_trajectory(trajectory([(0.5, offset(0.1))]))
    run(cm, 100)
    assert jtc.traj_time == 0.0 and jtc.desired_p == pytest.approx(HOME)


def test_joint_order_of_the_message_does_not_matter_and_an_empty_trajectory_stops():
    cm = make_manager(rate=100)
    jtc = spawn(cm, "jtc", JTC, {"joints": JOINTS})
    goal = offset(0.1)
    reversed_msg = trajectory([(0.2, goal[::-1])], joints=JOINTS[::-1])
    assert jtc.on_trajectory(reversed_msg)
    t = run(cm, 30)
    assert jtc.desired_p == pytest.approx(goal)
    jtc.on_trajectory(trajectory([(1.0, offset(0.3))]))
    t = run(cm, 20, start=t)
    moving = list(jtc.desired_p)
    assert jtc.on_trajectory(JointTrajectory(joint_names=list(JOINTS)))  # no points: stop here
    run(cm, 20, start=t)
    assert jtc.desired_p == pytest.approx(moving, abs=0.02) and jtc.desired_v == [0.0] * 6


def test_partial_goal_holds_the_other_joints_when_allowed():
    cm = make_manager(rate=100)
    jtc = spawn(cm, "jtc", JTC, {"joints": JOINTS, "allow_partial_joints_goal": True})
    assert jtc.on_trajectory(trajectory([(0.2, [0.3])], joints=["elbow_joint"]))
    run(cm, 60)  # 1.27 rad in 0.2 s is above the 3.14 rad/s limit: the limiter takes 0.4 s
    assert jtc.desired_p == pytest.approx(HOME[:2] + [0.3] + HOME[3:])
