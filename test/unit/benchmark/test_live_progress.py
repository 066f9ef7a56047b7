"""The monitor's progress line (ball_balance/benchmark/live.py, format_at) says what holds at its
stamp: DROPPED only while the truth shows the ball off the plate (the metrics still count the
drop after a reset put the ball back), and the tilt column, the command on /plate_cmd, is
labelled `cmd` and "not applied" while the robot manager is not active (emergency stop)."""
import math
from types import SimpleNamespace

import numpy as np

from ball_balance.benchmark.live import Recording, format_at, live_metrics, overlay_lines


def _header(t_s: float):
    sec = math.floor(t_s)
    return SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=round((t_s - sec) * 1e9)))


def _event(event: str, lifecycle_state: str):
    values = [SimpleNamespace(key=k, value=v) for k, v in
              (("event", event), ("source", "service"), ("lifecycle_state", lifecycle_state))]
    return SimpleNamespace(values=values)


def _transition(goal: str):
    return SimpleNamespace(goal_state=SimpleNamespace(label=goal))


def _run(rec, start_s, end_s, off_plate=lambda t: False, tilt=0.02):
    """Truth at 100 Hz, target and command at 50 Hz over [start_s, end_s)."""
    for t in np.arange(start_s, end_s, 0.01):
        off = off_plate(t)
        rec.on_truth(SimpleNamespace(header=_header(t), x=0.5 if off else 0.01, y=0.0, ball_found=not off))
    for t in np.arange(start_s, end_s, 0.02):
        rec.on_reference(SimpleNamespace(header=_header(t), point=SimpleNamespace(x=0.0, y=0.0)))
        rec.on_command(SimpleNamespace(header=_header(t), vector=SimpleNamespace(x=tilt, y=-tilt)))


def test_dropped_shows_while_the_ball_is_off_the_plate_not_after_a_reset_put_it_back():
    rec = Recording()
    _run(rec, 0.0, 10.0, off_plate=lambda t: 3.0 <= t < 5.0)   # dropped at 3 s, reset at 5 s
    rec.on_dropped(SimpleNamespace(data=True))
    rec.on_dropped(SimpleNamespace(data=False))                 # the latch after the reset
    assert "DROPPED" not in format_at(rec, 2.0)
    assert format_at(rec, 3.5).endswith("  DROPPED")
    back = format_at(rec, 6.0)
    assert "DROPPED" not in back and "ball (  +10.0,    +0.0) mm" in back
    # the run's figures still count the drop (and end where it happened)
    m = live_metrics(rec)
    assert m["drop"] == 1.0 and m["survived_s"] < 3.1


def test_the_commanded_tilt_is_marked_not_applied_while_the_robot_manager_is_not_active():
    rec = Recording()
    rec.on_manager_event(_event("state_change", "inactive"))   # configure, before the first truth
    rec.on_manager_transition(_transition("active"))
    rec.on_manager_event(_event("state_change", "active"))
    _run(rec, 0.0, 4.0)
    rec.on_manager_event(_event("emergency_stop", "active"))   # at the newest stamp read, ~4 s
    rec.on_manager_transition(_transition("inactive"))
    rec.on_manager_event(_event("state_change", "inactive"))
    _run(rec, 4.0, 8.0, tilt=0.15)
    applied, stopped = format_at(rec, 3.0), format_at(rec, 6.0)
    assert "  tilt (+1.15, -1.15) deg" in applied and "not applied" not in applied
    assert "  cmd  (+8.59, -8.59) deg" in stopped and stopped.endswith("  not applied (robot manager inactive)")
    assert len(stopped.split("  not applied")[0]) == len(applied)     # the columns keep their width
    assert rec.manager_at(4.5) == "inactive"
    assert overlay_lines(rec, 6.0)[1].endswith("not applied (robot manager inactive)")


def test_an_emergency_stop_alone_marks_the_command_not_applied_and_no_robot_manager_leaves_it_as_tilt():
    rec = Recording()
    _run(rec, 0.0, 2.0)
    assert "  tilt (+1.15, -1.15) deg" in format_at(rec, 1.0)   # no robot manager heard from
    rec.on_manager_event(_event("emergency_stop", "active"))
    _run(rec, 2.0, 4.0)
    assert format_at(rec, 3.0).endswith("  not applied (emergency stop)")
    assert "  tilt (" in format_at(rec, 1.0)                     # before the stop it was applied
