"""Per-message plausibility of ball states, the publisher lock and peer heartbeats (no ROS)."""
import math

from ball_balance.control.plausibility import BallStateGate, GateConfig, Heartbeat, SourceLock
from ball_balance.control.safety import BallObservation


def ball(x=0.0, y=0.0, vx=0.0, vy=0.0, valid=True):
    return BallObservation(x, y, vx, vy, valid, 4, 0.0)


def test_states_stamped_in_the_future_or_too_old_are_refused_with_the_reason():
    gate = BallStateGate(GateConfig(max_age_s=0.5, max_stamp_ahead_s=0.05))
    assert gate.check(100.0, 90.0, ball()).kind == "stale"
    assert "10.00 s old" in gate.check(100.0, 90.0, ball()).reason
    assert gate.check(100.0, 99.6, ball()).ok            # late, still worth predicting from
    assert gate.check(100.0, 110.0, ball()).kind == "future"
    assert gate.check(100.0, 100.03, ball()).ok          # within the clock tolerance
    assert gate.check(100.0, math.nan, ball()).kind == "non_finite"


def test_off_plate_too_fast_and_non_finite_states_are_refused():
    gate = BallStateGate(GateConfig())
    assert gate.check(1.0, 1.0, ball(x=5.0)).kind == "off_plate"
    assert gate.check(1.0, 1.0, ball(vx=3.0)).kind == "too_fast"
    assert gate.check(1.0, 1.0, ball(y=math.nan)).kind == "non_finite"
    assert gate.check(1.0, 1.0, ball(x=0.1)).ok


def test_a_state_not_newer_than_the_one_in_use_is_refused():
    gate = BallStateGate(GateConfig())
    assert gate.check(1.0, 1.0, ball()).ok
    assert gate.check(1.01, 1.0, ball()).kind == "old"
    assert gate.check(1.01, 0.99, ball()).kind == "old"


def test_interleaved_states_from_elsewhere_on_the_plate_never_replace_the_moving_ball():
    gate = BallStateGate(GateConfig(max_jump_m=0.03))
    t, x, accepted = 0.0, 0.0, []
    for _ in range(60):
        t += 1 / 60
        x += 0.1 / 60                              # the real ball rolls at 0.1 m/s
        accepted.append(gate.check(t, t, ball(x=x, vx=0.1)).ok)
        t += 1 / 60                                # a rogue at a fixed place in between
        assert gate.check(t, t, ball(x=-0.1, y=0.1)).kind == "jump"
    assert all(accepted)


def test_a_real_jump_is_accepted_once_three_states_agree():
    gate = BallStateGate(GateConfig(reacquire_count=3))
    assert gate.check(0.0, 0.0, ball(x=0.0)).ok
    verdicts = [gate.check(t, t, ball(x=0.1)).ok for t in (0.03, 0.06, 0.09, 0.12)]
    assert verdicts == [False, False, True, True]


def test_after_a_gap_the_first_state_is_taken_wherever_it_is():
    gate = BallStateGate(GateConfig(motion_window_s=0.5, max_age_s=0.25))
    assert gate.check(0.0, 0.0, ball(x=0.0)).ok
    assert gate.check(1.0, 1.0, ball(x=0.15)).ok


def test_invalid_tracking_states_pass_on_their_stamps_alone():
    gate = BallStateGate(GateConfig())
    assert gate.check(0.0, 0.0, ball(x=0.0)).ok
    assert gate.check(0.03, 0.03, ball(x=math.nan, valid=False)).ok
    assert gate.check(0.06, 0.06, ball(x=0.001)).ok


def test_source_lock_ignores_a_second_writer_and_follows_the_locked_one_through_losses():
    lock = SourceLock()
    assert lock.observe(0.0, 5000) == (True, "locked")
    for i in range(1, 60):
        assert lock.observe(i * 0.033, 5000 + 2 * i)[0]            # every other sample lost
        assert lock.observe(i * 0.033 + 0.01, i) == (False, "foreign")   # a rogue counting from 1


def test_source_lock_keeps_two_writers_apart_when_their_numbers_cross():
    lock = SourceLock(max_seq_gap=50)
    assert lock.observe(0.0, 100)[0]                   # the tracker at 30 Hz
    assert not lock.observe(0.001, 80)[0]              # a rogue at 60 Hz, 20 numbers behind
    t_real, t_rogue, real, rogue = 0.0, 0.001, 100, 80
    for _ in range(200):                               # the rogue overtakes after ~0.7 s
        t_real += 1 / 30
        real += 1
        while t_rogue + 1 / 60 < t_real:
            t_rogue += 1 / 60
            rogue += 1
            assert not lock.observe(t_rogue, rogue)[0], (rogue, real)
        assert lock.observe(t_real, real)[0], (rogue, real)


def test_source_lock_moves_to_a_restarted_tracker_only_when_allowed():
    lock = SourceLock(silence_s=3.0)
    assert lock.observe(0.0, 900)[0]
    assert lock.observe(2.0, 1) == (False, "foreign")              # a stall under load: still the lock
    assert lock.observe(2.1, 901) == (True, "")                    # ... and it resumes
    assert not lock.may_move(4.0) and lock.may_move(5.2)
    assert lock.observe(5.2, 2, relock_allowed=False) == (False, "ambiguous")
    assert lock.observe(5.3, 3, relock_allowed=True) == (True, "locked")
    assert lock.observe(5.4, 902) == (False, "foreign")            # the old stream is now the stranger


def test_source_lock_uses_the_publisher_gid_when_the_middleware_gives_it():
    lock = SourceLock()
    assert lock.observe(0.0, 7, gid=b"a" * 16) == (True, "locked")
    assert lock.observe(0.1, 8, gid=b"b" * 16) == (False, "foreign")
    assert lock.observe(0.2, 8, gid=b"a" * 16) == (True, "")


def test_without_sequence_numbers_every_message_passes_to_the_other_gates():
    lock = SourceLock()
    assert lock.observe(0.0, None) == (True, "")
    assert lock.observe(0.0, 0) == (True, "")


def test_heartbeat_reports_a_silent_peer_once_and_its_return_once():
    beat = Heartbeat(timeout_s=1.0)
    assert beat.check(5.0) == ""                   # never heard: not lost (still starting)
    beat.beat(5.0)
    assert beat.check(5.5) == ""
    assert beat.check(6.2) == "lost" and beat.lost
    assert beat.check(7.0) == ""
    beat.beat(8.0)
    assert beat.check(8.1) == "back" and not beat.lost
    assert beat.check(8.2) == ""
