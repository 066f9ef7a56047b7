"""The joint command ramp and the command interval estimate, directly."""
import pytest

from controller_manager_py.controllers.command_ramp import CommandIntervalEstimate, CommandRamp


def test_the_command_ramp_runs_in_a_straight_line_from_the_last_command_to_the_target():
    ramp = CommandRamp(2)
    ramp.start([0.0, 1.0], [0.6, 0.4], t_from_s=1.0, duration_s=0.02)
    assert ramp.at(0.9).tolist() == [0.0, 1.0]                       # before: where it was
    assert ramp.at(1.005) == pytest.approx([0.15, 0.85])             # a quarter of the way
    assert ramp.at(1.02) == pytest.approx([0.6, 0.4])
    assert ramp.at(5.0) == pytest.approx([0.6, 0.4])                 # after: it stays at the target
    out = ramp.at(1.01)
    assert ramp.at(1.015) is out                                     # one array, reused (no allocation)


def test_the_interval_estimate_takes_the_first_interval_then_averages_bounded_ones():
    estimate = CommandIntervalEstimate(ceiling_s=0.05, weight=0.5)
    assert estimate.arrived(1.0) == 0.05                # one command: the ceiling
    assert estimate.arrived(1.02) == pytest.approx(0.02)   # the first interval as it is
    assert estimate.arrived(1.04) == pytest.approx(0.02)
    assert estimate.arrived(3.0) == pytest.approx(0.035)   # a pause counts as the ceiling
    estimate.reset()                                     # a new stream: no interval across it
    assert estimate.arrived(10.0) == pytest.approx(0.035)
    assert estimate.arrived(10.02) == pytest.approx(0.0275)


def test_retarget_starts_one_update_back_from_what_was_written_or_the_target_itself():
    ramp = CommandRamp(1)
    target = [1.0]
    ramp.retarget(target, [0.0], t_s=1.0, period_s=0.002, duration_s=0.02)
    assert ramp.target is target
    assert ramp.at(1.0) == pytest.approx([0.1])        # this update already moves: one of ten
    ramp.retarget([2.0], [float("nan")], t_s=2.0, period_s=0.002, duration_s=0.0)
    assert ramp.at(2.0) == pytest.approx([2.0])        # nothing written yet; at least one update
