import math

from ball_balance.control.safety import BallObservation, Mode, SafetyConfig, SafetySupervisor


def obs(**kw):
    base = dict(x=0.0, y=0.0, vx=0.0, vy=0.0, tracking_valid=True, markers_found=4, age_s=0.02)
    base.update(kw)
    return BallObservation(**base)


def test_homes_first_and_engages_only_at_home_with_a_healthy_state():
    s = SafetySupervisor(SafetyConfig())
    assert s.update(0.0, obs(), at_home=False) == Mode.HOMING
    assert s.update(0.1, obs(), at_home=True) == Mode.READY
    assert s.update(0.2, obs(markers_found=2), at_home=True) == Mode.READY
    assert s.update(0.3, obs(), at_home=True) == Mode.ENGAGED
    assert s.reset_requested


def _engaged():
    s = SafetySupervisor(SafetyConfig(loss_hold_s=0.3))
    s.update(0.0, obs(), True)
    s.update(0.0, obs(), True)
    assert s.mode == Mode.ENGAGED
    return s


def test_short_loss_holds_and_recovers_after_a_healthy_run():
    s = _engaged()
    assert s.update(1.0, obs(tracking_valid=False), True) == Mode.HOLDING
    assert s.update(1.2, obs(tracking_valid=False), True) == Mode.HOLDING
    assert s.update(1.25, obs(), True) == Mode.HOLDING     # healthy, not yet for healthy_before_engage_s
    assert s.update(1.36, obs(), True) == Mode.ENGAGED
    assert "recovered" in s.reason


def test_a_state_alternately_fresh_and_late_holds_on_without_flip_flops_or_going_home():
    s = _engaged()
    modes = [s.update(1.0 + 0.02 * i, obs(age_s=0.3 if i % 2 == 0 else 0.02), False) for i in range(100)]
    assert set(modes) == {Mode.HOLDING}                    # acted on through prediction, one mode change


def test_a_state_too_old_to_predict_from_goes_home_after_grace_despite_fresh_flashes():
    s = SafetySupervisor(SafetyConfig(loss_hold_s=0.3, max_late_s=0.5))
    s.update(0.0, obs(), True)
    s.update(0.0, obs(), True)
    modes = [s.update(1.0 + 0.02 * i, obs(age_s=0.02 if i % 4 == 3 else 0.6), False) for i in range(40)]
    assert Mode.ENGAGED not in modes and modes[-1] == Mode.RETURNING
    assert "stale" in s.reason


def test_two_markers_with_a_good_pose_covariance_stay_engaged():
    s = _engaged()
    assert s.update(1.0, obs(markers_found=2, position_std_m=0.0007), True) == Mode.ENGAGED
    assert s.update(1.1, obs(markers_found=1, position_std_m=0.004), True) == Mode.ENGAGED


def test_a_pose_too_uncertain_to_act_on_holds_whatever_the_marker_count():
    s = _engaged()
    assert s.update(1.0, obs(markers_found=4, position_std_m=0.02), True) == Mode.HOLDING
    assert "position std 20.0 mm" in s.reason
    assert not s.healthy(obs(position_std_m=float("inf")))[0]
    assert not s.healthy(obs(position_std_m=float("nan")))[0]
    assert not s.usable_except_age(obs(position_std_m=float("inf"), age_s=1.0))
    assert s.usable_except_age(obs(markers_found=2, position_std_m=0.001, age_s=1.0))


def test_without_a_pose_figure_the_markers_rule_decides():
    s = SafetySupervisor(SafetyConfig(min_markers=3))
    assert not s.healthy(obs(markers_found=2))[0]
    assert s.healthy(obs(markers_found=3))[0]


def test_loss_beyond_grace_returns_home_and_resets_integrators():
    s = _engaged()
    s.update(1.0, obs(markers_found=0), False)
    assert s.update(1.31, obs(markers_found=0), False) == Mode.RETURNING
    assert s.reset_requested
    assert s.update(1.4, obs(markers_found=0), False) == Mode.RETURNING
    assert s.update(2.0, obs(markers_found=0), True) == Mode.READY
    assert s.update(2.1, obs(), True) == Mode.ENGAGED


def test_a_ball_seen_again_on_the_way_home_is_taken_up_after_a_healthy_run():
    s = _engaged()
    s.update(1.0, obs(markers_found=0), False)
    assert s.update(1.31, obs(markers_found=0), False) == Mode.RETURNING
    assert s.update(1.40, obs(), False) == Mode.RETURNING     # healthy, not yet for healthy_before_engage_s
    assert s.update(1.45, obs(age_s=0.4), False) == Mode.RETURNING   # a break restarts the run
    assert s.update(1.50, obs(), False) == Mode.RETURNING
    assert s.update(1.61, obs(), False) == Mode.ENGAGED
    assert s.reset_requested and "re-acquired" in s.reason


def test_stale_nan_and_off_plate_states_are_unhealthy():
    s = SafetySupervisor(SafetyConfig(ball_state_max_age_s=0.25))
    assert not s.healthy(obs(age_s=0.3))[0]
    assert "stale" in s.healthy(obs(age_s=0.3))[1]
    assert not s.healthy(obs(x=math.nan))[0]
    assert not s.healthy(obs(x=0.3))[0]
    assert not s.healthy(None)[0]
    assert s.healthy(obs())[0]
