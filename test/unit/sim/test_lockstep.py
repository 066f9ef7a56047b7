"""Lock-step with the control chain (ball_balance/sim/lockstep.py): the simulation holds before
the next camera frame until the last one is answered, in MujocoSystem's loop and in the gate."""
import logging

import pytest

from ball_balance import robot
from ball_balance.sim.lockstep import FrameAnswerGate, PaceReport
from controller_manager_py.hardware_interface import CallbackReturn, State, parse_control_resources, return_type
from controller_manager_py.plugins import HARDWARE_GROUP, load_class

PERIOD_S = 0.002
RATE_HZ = 50.0


class FakeWall:
    def __init__(self):
        self.now_s = 100.0

    def __call__(self):
        return self.now_s


@pytest.fixture
def wall():
    return FakeWall()


@pytest.fixture
def system(wall):
    description = robot.robot_description("mujoco", {"camera_enabled": False, "camera_rate_hz": RATE_HZ})
    (info,) = parse_control_resources(description)
    system = load_class(HARDWARE_GROUP, "ball_balance/MujocoSystem")()
    system._attach(None, logging.getLogger("test_lockstep"))
    assert system.on_init(info) == CallbackReturn.SUCCESS
    assert system.on_configure(State.UNCONFIGURED) == CallbackReturn.SUCCESS
    assert system.on_activate(State.INACTIVE) == CallbackReturn.SUCCESS
    system.answers = FrameAnswerGate(timeout_wall_s=5.0, wall_clock=wall)   # as with a ROS node
    captured = []
    original = system.answers.frame_captured
    system.answers.frame_captured = lambda t: (captured.append(t), original(t))
    system.captured = captured
    yield system
    system.on_shutdown(State.ACTIVE)


def cycles(system, n, wall=None):
    for _ in range(n):
        if wall is not None:
            wall.now_s += PERIOD_S
        assert system.read(system.now(), PERIOD_S) == return_type.OK


def answer(system, time_s):
    system.answers.on_state(time_s)
    system.answers.on_command()


def test_runs_free_until_an_answer_is_seen(system):
    cycles(system, 100)   # 0.2 s: frames captured every 20 ms, none answered, no waiting
    assert system.now() == pytest.approx(0.2)
    assert len(system.captured) >= 10


def test_holds_one_frame_period_after_an_unanswered_frame(system, wall):
    cycles(system, 1)
    answer(system, system.captured[-1])          # answers are coming from now on
    cycles(system, 12)                           # the next frame is captured (t = 20 ms) ...
    frame = system.captured[-1]
    assert frame == pytest.approx(1 / RATE_HZ, abs=PERIOD_S)
    cycles(system, 200, wall)                    # ... and not answered: time stops at the next one's capture
    assert system.now() == pytest.approx(frame + 1 / RATE_HZ, abs=1.5 * PERIOD_S)
    assert system.captured[-1] == frame
    answer(system, frame)
    cycles(system, 1)                            # answered: the held frame is captured, time goes on
    assert system.captured[-1] == pytest.approx(frame + 1 / RATE_HZ, abs=1.5 * PERIOD_S)
    cycles(system, 3)
    assert system.now() > frame + 1 / RATE_HZ + PERIOD_S


def test_a_command_before_the_frames_state_is_not_its_answer(system, wall):
    cycles(system, 1)
    answer(system, system.captured[-1])
    cycles(system, 12)
    frame = system.captured[-1]
    system.answers.on_state(frame - 1 / RATE_HZ)   # the previous frame's state, late
    system.answers.on_command()
    cycles(system, 50, wall)
    assert system.captured[-1] == frame           # still held
    system.answers.on_state(frame)
    system.answers.on_command()
    cycles(system, 1)
    assert system.captured[-1] > frame


def test_a_frame_never_answered_is_given_up_after_the_timeout(system, wall):
    cycles(system, 1)
    answer(system, system.captured[-1])
    cycles(system, 30)
    held_at = system.now()
    wall.now_s += 6.0
    cycles(system, 5)
    assert system.answers.frames_given_up == 1
    assert system.now() == pytest.approx(held_at + 5 * PERIOD_S)
    cycles(system, 50)                            # no answers since: no more waiting
    assert system.answers.frames_given_up == 1


def test_pace_report_states_the_real_time_factor_and_why(wall):
    class World:
        time_s = 0.0

    class Camera:
        last_render_s = 0.040

    gate = FrameAnswerGate(wall_clock=wall)
    report = PaceReport(gate, Camera(), World(), 1 / 60)
    assert report.line(wall.now_s) == ""
    gate.wait_wall_s = 6.0
    World.time_s = 2.5
    line = report.line(wall.now_s + 10.0)
    assert "0.25x real time" in line and "60 %" in line and "40.0 ms" in line and "slows down" in line
    World.time_s = 5.0
    assert "slows down" not in report.line(wall.now_s + 20.0)   # explained once


def test_a_controller_in_this_process_answers_with_the_states_arrival(system, wall):
    cycles(system, 1)
    system.answers.answer_on_state = True
    system.answers.on_state(system.captured[-1])   # no /plate_cmd needed
    cycles(system, 12)
    frame = system.captured[-1]
    cycles(system, 50, wall)
    assert system.captured[-1] == frame            # held until its state arrives
    system.answers.on_state(frame)
    cycles(system, 1)
    assert system.captured[-1] > frame


def test_waiting_starts_even_when_the_chain_is_slower_than_a_frame_from_the_start(system, wall):
    """Running free, a slow chain answers an older frame than the newest: that answer counts."""
    cycles(system, 40)                             # several frames captured, none answered
    assert len(system.captured) >= 3
    answer(system, system.captured[0])            # the first frame's answer, late
    newest = system.captured[-1]
    cycles(system, 100, wall)
    assert system.captured[-1] == newest           # held before the next capture
    assert system.now() == pytest.approx(newest + 1 / RATE_HZ, abs=1.5 * PERIOD_S)
    assert system.answers.must_wait()
    answer(system, system.captured[-2])            # an answer to a frame before the newest: still held
    assert system.answers.must_wait()
    answer(system, system.captured[-1])
    assert not system.answers.must_wait()
