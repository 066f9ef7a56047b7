"""Trajectory goals in the loop (no ROS): tolerances, success, aborts that hold the arm,
preemption, cancel, and trajectories beyond the joint limits (the 50 rad case)."""
import pytest
from cm_helpers import HOME, JOINTS, MOCK_UR, make_manager, positions, run
from control_msgs.msg import JointTolerance
from test_joint_trajectory import JTC, offset, trajectory

from controller_manager_py.controllers import tolerances as tol
from controller_manager_py.controllers.joint_trajectory import (
    GOAL_TOLERANCE_VIOLATED,
    INVALID_GOAL,
    PATH_TOLERANCE_VIOLATED,
    SUCCESSFUL,
    GoalRun,
    TrajectoryError,
)
from controller_manager_py.hardware_interface.types import JointLimits

RATE = 100


def spawn_jtc(cm, params=None, urdf=MOCK_UR):
    """The trajectory controller with the robot description (its joint limits) handed over."""
    cm.load_controller("jtc", JTC, {"joints": JOINTS, **(params or {})})
    cm.controllers["jtc"].c.robot_description = urdf
    cm.configure_controller("jtc")
    cm.switch_controller(["jtc"], [], 2)
    return cm.controllers["jtc"].c


def goal_run(jtc, path=(), goal=(), goal_time=0.0):
    tolerances, problem = tol.goal_tolerances(jtc.default_tolerances, jtc.joints, list(path), list(goal), goal_time)
    assert problem is None
    return GoalRun(tolerances)


def send(jtc, msg, run):
    jtc.offer(jtc.accept(msg, run))
    return run


def every_joint(**values):
    return [JointTolerance(name=j, **values) for j in JOINTS]


def cycles_until(cm, predicate, start, limit=1000):
    t = start
    for _ in range(limit):
        if predicate():
            return t
        t = run(cm, 1, start=t)
    raise AssertionError("condition not reached")


# ---- tolerances (pure) -------------------------------------------------------------------
def test_goal_tolerance_zero_keeps_the_default_and_minus_one_erases_it():
    assert tol.resolve(0.2, 0.0) == 0.2
    assert tol.resolve(0.2, 0.05) == 0.05
    assert tol.resolve(0.2, -1.0) == 0.0
    with pytest.raises(ValueError):
        tol.resolve(0.2, -0.5)


def test_a_goal_with_an_unknown_joint_tolerance_uses_the_defaults_and_says_why():
    defaults = tol.Tolerances([tol.StateTolerance(0.1)], [tol.StateTolerance(0.01, 0.2)], 1.0)
    result, problem = tol.goal_tolerances(defaults, ["a"], [JointTolerance(name="b", position=0.3)], [], 0.0)
    assert result is defaults and "'b'" in problem
    result, problem = tol.goal_tolerances(defaults, ["a"], [JointTolerance(name="a", position=-1.0)],
                                          [JointTolerance(name="a", velocity=0.5)], 2.0)
    assert problem is None
    assert (result.path[0].position, result.goal[0].position, result.goal[0].velocity, result.goal_time) == \
        (0.0, 0.01, 0.5, 2.0)


def test_limits_refuse_unreachable_points_and_impossible_waypoint_velocities():
    limits = {"a": JointLimits(min_position=-3.0, max_position=3.0, max_velocity=1.0),
              "off": JointLimits(min_position=-1.0, max_position=1.0, disabled=frozenset({"*"}))}
    assert "outside its position limits" in tol.check_limits(["a"], limits, [[50.0]], None, [True])
    assert "exceeds its limit" in tol.check_limits(["a"], limits, [[0.5]], [[1.5]], [True])
    assert tol.check_limits(["a"], limits, [[3.0], [-3.0]], [[1.0], [0.0]], [True]) is None
    assert tol.check_limits(["a", "off"], limits, [[50.0, 50.0]], None, [False, True]) is None


# ---- goals in the loop ---------------------------------------------------------------------
def test_goal_succeeds_with_the_arm_at_the_goal():
    cm = make_manager(rate=RATE)
    jtc = spawn_jtc(cm)
    run_ = send(jtc, trajectory([(0.3, offset(0.05)), (0.6, offset(0.1))]),
                goal_run(jtc, goal=every_joint(position=1e-3)))
    cycles_until(cm, lambda: run_.outcome is not None, 0.0)
    assert run_.outcome[:2] == (GoalRun.SUCCEEDED, SUCCESSFUL)
    assert positions(cm) == pytest.approx(offset(0.1), abs=1e-3)


def test_path_tolerance_violation_aborts_and_holds_where_the_arm_is():
    cm = make_manager(rate=RATE)
    jtc = spawn_jtc(cm)
    # the mock follows one cycle late: about v * dt of error while moving, above 1e-5 rad
    run_ = send(jtc, trajectory([(1.0, offset(0.3))]), goal_run(jtc, path=every_joint(position=1e-5)))
    t = cycles_until(cm, lambda: run_.outcome is not None, 0.0)
    assert run_.outcome[:2] == (GoalRun.ABORTED, PATH_TOLERANCE_VIOLATED) and "path tolerance" in run_.outcome[2]
    held = positions(cm)
    run(cm, 50, start=t)
    assert positions(cm) == pytest.approx(held, abs=0.01)  # stopped: not on its way to the goal
    assert positions(cm)[0] < HOME[0] + 0.1
    assert jtc.desired_p == pytest.approx(positions(cm), abs=0.01)


def test_goal_tolerance_not_met_within_goal_time_aborts():
    urdf = MOCK_UR.replace('<param name="calculate_dynamics">true</param>',
                           '<param name="calculate_dynamics">true</param>'
                           '<param name="position_state_following_offset">0.05</param>')
    cm = make_manager(rate=RATE, urdf=urdf)
    jtc = spawn_jtc(cm, urdf=urdf)
    run_ = send(jtc, trajectory([(0.2, offset(0.05))]), goal_run(jtc, goal=every_joint(position=0.01), goal_time=0.3))
    cycles_until(cm, lambda: run_.outcome is not None, 0.0)
    assert run_.outcome[:2] == (GoalRun.ABORTED, GOAL_TOLERANCE_VIOLATED)
    assert "goal_time_tolerance" in run_.outcome[2]


def test_new_goal_preempts_the_running_one():
    cm = make_manager(rate=RATE)
    jtc = spawn_jtc(cm)
    first = send(jtc, trajectory([(1.0, offset(0.3))]), goal_run(jtc))
    t = run(cm, 20)
    second = send(jtc, trajectory([(0.5, offset(-0.1))]), goal_run(jtc))
    assert first.outcome[:2] == (GoalRun.ABORTED, INVALID_GOAL) and "preempted" in first.outcome[2]
    cycles_until(cm, lambda: second.outcome is not None, t)
    assert second.outcome[0] == GoalRun.SUCCEEDED
    assert positions(cm) == pytest.approx(offset(-0.1), abs=1e-6)


def test_hold_stops_the_arm_where_it_is():
    cm = make_manager(rate=RATE)
    jtc = spawn_jtc(cm)
    send(jtc, trajectory([(1.0, offset(0.3))]), goal_run(jtc))
    t = run(cm, 40)
    jtc.hold()
    t = run(cm, 2, start=t)
    held = positions(cm)
    run(cm, 100, start=t)
    assert positions(cm) == pytest.approx(held, abs=1e-9)
    assert HOME[0] + 0.05 < held[0] < HOME[0] + 0.3


DECELERATION = 2.0  # rad/s^2
BRAKING = {"constraints.decelerate_on_cancel": True,
           **{f"constraints.{j}.max_deceleration_on_cancel": DECELERATION for j in JOINTS}}


def brake_and_record(cm, t, cycles=60):
    """Positions of joint 0 over `cycles` cycles (the stop is planned at the first)."""
    path = [positions(cm)[0]]
    for _ in range(cycles):
        t = run(cm, 1, start=t)
        path.append(positions(cm)[0])
    return path, t


def test_cancel_with_decelerate_on_cancel_brakes_to_rest_at_the_deceleration():
    cm = make_manager(rate=RATE)
    jtc = spawn_jtc(cm, BRAKING)
    send(jtc, trajectory([(1.0, offset(0.3))]), goal_run(jtc))
    t = run(cm, 40)
    p0, v0 = jtc.desired_p[0], jtc.desired_v[0]  # commanded: braking starts from there
    assert v0 > 0.3  # mid-way, moving
    jtc.cancel()
    path, t = brake_and_record(cm, t)
    rest = p0 + v0 * v0 / (2 * DECELERATION)  # where constant braking from (p0, v0) ends
    assert path[-1] == pytest.approx(rest, abs=1e-6)
    assert path[-1] == pytest.approx(path[-20], abs=1e-9)  # at rest, well before the end
    steps = [b - a for a, b in zip(path, path[1:])]
    assert all(step >= -1e-12 for step in steps)  # never turns back
    braking = [(b - a) * RATE * RATE for a, b in zip(steps[1:], steps[2:])]
    assert max(abs(x) for x in braking) <= 1.2 * DECELERATION


def test_abort_with_decelerate_on_cancel_brakes_instead_of_stopping_dead():
    cm = make_manager(rate=RATE)
    jtc = spawn_jtc(cm, BRAKING)
    run_ = send(jtc, trajectory([(1.0, offset(0.3))]), goal_run(jtc))
    t = run(cm, 40)
    run_.tolerances.path[0].position = 1e-5  # the mock follows one cycle late: violated next cycle
    path, t = brake_and_record(cm, t)
    assert run_.outcome[:2] == (GoalRun.ABORTED, PATH_TOLERANCE_VIOLATED)
    assert path[-1] - path[1] > 0.02 and path[-1] == pytest.approx(path[-20], abs=1e-9)


def test_decelerate_on_cancel_without_every_deceleration_holds_and_says_why(caplog):
    cm = make_manager(rate=RATE)
    jtc = spawn_jtc(cm, {**BRAKING, f"constraints.{JOINTS[0]}.max_deceleration_on_cancel": 0.0})
    assert jtc.stop_decelerations is None
    send(jtc, trajectory([(1.0, offset(0.3))]), goal_run(jtc))
    t = run(cm, 40)
    jtc.cancel()
    t = run(cm, 2, start=t)
    held = positions(cm)
    run(cm, 50, start=t)
    assert positions(cm) == pytest.approx(held, abs=1e-9)


def test_unreachable_point_is_refused_and_the_controller_never_diverges_from_the_arm():
    """A goal of 50 rad, then a valid trajectory home."""
    cm = make_manager(rate=RATE)
    jtc = spawn_jtc(cm)
    with pytest.raises(TrajectoryError, match="outside its position limits"):
        jtc.accept(trajectory([(2.0, [50.0] + HOME[1:])]))
    assert not jtc.on_trajectory(trajectory([(2.0, [50.0] + HOME[1:])]))
    assert jtc.refused == 2
    t = run(cm, 50)
    assert jtc.desired_p == pytest.approx(HOME) and positions(cm) == pytest.approx(HOME)
    assert jtc.on_trajectory(trajectory([(1.0, offset(0.2))]))
    t = run(cm, 60, start=t)
    assert jtc.on_trajectory(trajectory([(1.5, HOME)]))
    run(cm, 200, start=t)
    assert positions(cm) == pytest.approx(HOME, abs=1e-9)
    assert jtc.desired_p == pytest.approx(positions(cm), abs=1e-9)


def test_too_fast_trajectory_is_followed_as_fast_as_the_limits_allow():
    cm = make_manager(rate=RATE)
    jtc = spawn_jtc(cm)
    assert jtc.on_trajectory(trajectory([(0.1, offset(1.0))]))  # 10 rad/s asked, 3.14 allowed
    t = run(cm, 20)
    assert jtc.clamped > 0
    assert jtc.desired_p == pytest.approx(positions(cm), abs=3.14 / RATE + 1e-9)  # commanded = followed
    run(cm, 100, start=t)
    assert positions(cm) == pytest.approx(offset(1.0), abs=1e-9)


def test_query_samples_the_active_trajectory():
    cm = make_manager(rate=RATE)
    jtc = spawn_jtc(cm)
    assert jtc.sample(0.0) is None
    jtc.on_trajectory(trajectory([(1.0, offset(0.2))]))
    t = run(cm, 10)
    p, v, a = jtc.sample(t + 0.9)
    assert HOME[0] + 0.15 < p[0] < HOME[0] + 0.2 and v[0] > 0.0
    assert jtc.sample(t + 5.0) is None


def test_deactivation_ends_the_running_goal():
    cm = make_manager(rate=RATE)
    jtc = spawn_jtc(cm)
    run_ = send(jtc, trajectory([(1.0, offset(0.3))]), goal_run(jtc))
    run(cm, 10)
    cm.switch_controller([], ["jtc"], 2)
    assert run_.outcome[:2] == (GoalRun.ABORTED, INVALID_GOAL)


def test_trajectory_that_ends_in_the_past_is_refused():
    cm = make_manager(rate=RATE)
    jtc = spawn_jtc(cm)
    run(cm, 300)  # manager time 3 s
    old = trajectory([(1.0, offset(0.1))])
    old.header.stamp.sec = 1  # started at 1 s, ended at 2 s
    with pytest.raises(TrajectoryError, match="in the past"):
        jtc.accept(old)
    old.header.stamp.sec = 2  # ends at 3.0 + a bit: still running
    old.points[0].time_from_start.nanosec = 500_000_000
    jtc.accept(old)
