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
    s = SafetySupervisor(SafetyConfig(grace_s=0.3))
    s.update(0.0, obs(), True)
    s.update(0.0, obs(), True)
    assert s.mode == Mode.ENGAGED
    return s


def test_short_loss_holds_and_recovers():
    s = _engaged()
    assert s.update(1.0, obs(tracking_valid=False), True) == Mode.HOLDING
    assert s.update(1.2, obs(tracking_valid=False), True) == Mode.HOLDING
    assert s.update(1.25, obs(), True) == Mode.ENGAGED


def test_loss_beyond_grace_returns_home_and_resets_integrators():
    s = _engaged()
    s.update(1.0, obs(markers_found=0), False)
    assert s.update(1.31, obs(markers_found=0), False) == Mode.RETURNING
    assert s.reset_requested
    assert s.update(1.4, obs(), False) == Mode.RETURNING   # not until home
    assert s.update(2.0, obs(), True) == Mode.READY
    assert s.update(2.1, obs(), True) == Mode.ENGAGED


def test_stale_nan_and_off_plate_states_are_unhealthy():
    s = SafetySupervisor(SafetyConfig(stale_after_s=0.25))
    assert not s.healthy(obs(age_s=0.3))[0]
    assert "stale" in s.healthy(obs(age_s=0.3))[1]
    assert not s.healthy(obs(x=math.nan))[0]
    assert not s.healthy(obs(x=0.3))[0]
    assert not s.healthy(None)[0]
    assert s.healthy(obs())[0]
