"""The whole tick (safety, prediction, controller, IK, shaping) on a plant driven by the
tilt the commanded joints actually produce."""
import math
from collections import deque

import numpy as np
import pytest
from control_plant import K_G, DelayedPlant
from test_control_kinematics import LEVEL_HOME, UR_JOINTS, URDF

from ball_balance.control.estimation import EstimatorConfig, level_offset_rad
from ball_balance.control.kinematics import Chain, PlateKinematics, ShaperConfig
from ball_balance.control.pipeline import TILT_LAWS, ControlPipeline, PipelineConfig, make_tilt_law, register_tilt_law
from ball_balance.control.references import Circle, Stationary
from ball_balance.control.safety import BallObservation, Mode

DT = 0.02
STEP = 0.03


def _pipeline(controller, mode="wrist", reference=None, **cfg):
    kin = PlateKinematics(Chain.from_urdf(URDF.read_text(), UR_JOINTS), LEVEL_HOME,
                          shaper=ShaperConfig(max_joint_step_rad=STEP), mode=mode)
    return ControlPipeline(PipelineConfig(controller=controller, **cfg), kin, reference or Stationary())


def _observe(plant, **kw):
    values = dict(x=plant.p[0], y=plant.p[1], vx=plant.v[0], vy=plant.v[1], tracking_valid=True,
                  markers_found=4, age_s=0.0)
    values.update(kw)
    return BallObservation(**values)


@pytest.mark.parametrize("controller, mode", [("pid", "wrist"), ("mpc", "wrist"), ("pid", "pivot"),
                                              ("mpc", "pivot")])
def test_homes_engages_and_balances_an_off_centre_ball(controller, mode):
    pipe = _pipeline(controller, mode)
    plant = DelayedPlant(x0=(0.08, -0.06))
    q_prev = np.array(LEVEL_HOME) + 0.2   # start away from home
    modes = []
    for i in range(int(8.0 / DT)):
        result = pipe.step(i * DT, _observe(plant), q_prev)
        assert np.max(np.abs(result.q_cmd - q_prev)) <= STEP + 1e-12
        q_prev = result.q_cmd
        modes.append(result.mode)
        tilt = pipe.kin.tilt_of(result.q_cmd) if result.mode != Mode.HOMING else (0.0, 0.0)
        plant.advance(tilt, DT)
    assert modes[0] == Mode.HOMING and modes[-1] == Mode.ENGAGED
    assert np.linalg.norm(plant.p) < 0.005


def test_nan_and_lost_markers_hold_then_return_home_without_jumps():
    pipe = _pipeline("pid", brake_on_loss_s=0.0)   # braking off: the last tilt is held
    plant = DelayedPlant(x0=(0.05, 0.0))
    q_prev = np.array(LEVEL_HOME)
    for i in range(25):
        q_prev = pipe.step(i * DT, _observe(plant), q_prev).q_cmd
    assert pipe.safety.mode == Mode.ENGAGED and pipe.u[0] > 0
    held = pipe.u.copy()
    bad = [_observe(plant, x=math.nan), _observe(plant, markers_found=0), _observe(plant, age_s=1.0)]
    modes = []
    for i in range(25, 100):
        result = pipe.step(i * DT, bad[i % 3], q_prev)
        assert np.all(np.isfinite(result.q_cmd))
        assert np.max(np.abs(result.q_cmd - q_prev)) <= STEP + 1e-12
        q_prev = result.q_cmd
        modes.append(result.mode)
        if result.mode == Mode.HOLDING and i % 3 != 2:  # NaN / no markers: the last tilt is held
            assert result.u == tuple(held)
        held = np.array(result.u)
    assert modes[0] == Mode.HOLDING and Mode.RETURNING in modes
    assert modes[-1] == Mode.READY
    np.testing.assert_allclose(q_prev, LEVEL_HOME, atol=0.011)


class _ConstantLaw:
    """A stand-in for a plugged-in law (e.g. a learned policy): records what it is given."""

    def __init__(self, cfg):
        self.cfg, self.contexts, self.resets = cfg, [], 0

    def reset(self):
        self.resets += 1

    def tilt(self, ctx):
        self.contexts.append(ctx)
        return (0.01, -0.02)


def test_a_registered_tilt_law_drives_the_plate_through_the_same_pipeline():
    register_tilt_law("constant_for_test", _ConstantLaw)
    try:
        kin = PlateKinematics(Chain.from_urdf(URDF.read_text(), UR_JOINTS), LEVEL_HOME,
                              shaper=ShaperConfig(max_joint_step_rad=STEP))
        pipe = ControlPipeline(PipelineConfig(controller="constant_for_test", law_params={"x": 1},
                                              engage_accel_m_s2=0.0), kin, Stationary())
        plant = DelayedPlant(x0=(0.02, 0.0))
        q = np.array(LEVEL_HOME)
        for i in range(20):
            result = pipe.step(i * DT, _observe(plant), q)
            q = result.q_cmd
        assert result.mode == Mode.ENGAGED and result.u == (0.01, -0.02)
        ctx = pipe.law.contexts[-1]
        assert pipe.law.cfg.law_params == {"x": 1}
        assert ctx.pos_m.shape == (2,) and tuple(ctx.ref.p) == (0.0, 0.0) and ctx.dt_s == pytest.approx(DT)
        np.testing.assert_allclose(pipe.kin.tilt_of(q), (0.01, -0.02), atol=1e-6)
    finally:
        TILT_LAWS.pop("constant_for_test")


def test_an_unknown_or_missing_tilt_law_is_refused_by_name():
    with pytest.raises(ValueError, match="unknown controller 'nope'"):
        make_tilt_law(PipelineConfig(controller="nope"))
    register_tilt_law("missing_for_test", "ball_balance.no_such_module:make")
    try:
        with pytest.raises(ValueError, match="controller 'missing_for_test' is not available"):
            make_tilt_law(PipelineConfig(controller="missing_for_test"))
    finally:
        TILT_LAWS.pop("missing_for_test")


def _circle_then_lost(brake_on_loss_s):
    """A ball tracked on a circle (r 0.1 m, 5 s lap), then the tracking is lost for good."""
    pipe = _pipeline("pid", mode="pivot", reference=Circle(0.1, 5.0), brake_on_loss_s=brake_on_loss_s)
    plant = DelayedPlant(x0=(0.1, 0.0))
    q = np.array(LEVEL_HOME)
    speeds, tilts = [], []
    for i in range(int(14.0 / DT)):
        lost = i * DT >= 10.0
        result = pipe.step(i * DT, _observe(plant, tracking_valid=not lost), q)
        q = result.q_cmd
        tilt = pipe.kin.tilt_of(q) if result.mode != Mode.HOMING else (0.0, 0.0)
        plant.advance(tilt, DT)
        if lost:
            speeds.append(np.linalg.norm(plant.v))
            tilts.append(np.max(np.abs(tilt)))
    return pipe, plant, np.array(speeds), np.array(tilts)


def test_a_ball_lost_while_moving_is_braked_before_the_plate_levels():
    pipe, plant, speeds, tilts = _circle_then_lost(brake_on_loss_s=0.8)
    assert speeds[0] > 0.1                               # it was moving (2 pi 0.1 / 5 = 0.126 m/s)
    assert speeds[-1] < 0.15 * speeds[0]                 # braked: nearly at rest when level
    assert np.linalg.norm(plant.p) < 0.2                 # still on the plate (half side 0.2285)
    assert np.max(tilts[int(1.0 / DT):]) < 0.002         # bounded: level again after the braking
    assert pipe.safety.mode == Mode.READY
    # without braking the plate levels with the ball still rolling at full speed
    _, plant_off, speeds_off, _ = _circle_then_lost(brake_on_loss_s=0.0)
    assert speeds_off[-1] > 0.7 * speeds_off[0]


def _circle_error_on_a_half_gain_plant(controller, adapt):
    """RMS tracking error over the last 4 s of a 12 s circle on a plant at half the model's k g
    (half gravity) with a constant push (plate not level)."""
    estimator = EstimatorConfig(adapt_gain=adapt, adapt_offset=adapt)
    pipe = _pipeline(controller, mode="pivot", reference=Circle(0.08, 8.0), estimator=estimator)
    plant = DelayedPlant(x0=(0.08, 0.0), k_g=0.5 * K_G)
    offset_tilt = np.array([0.01, -0.005])          # a plate 0.6 degrees off level
    q = np.array(LEVEL_HOME)
    errors = []
    for i in range(int(12.0 / DT)):
        result = pipe.step(i * DT, _observe(plant), q)
        q = result.q_cmd
        tilt = pipe.kin.tilt_of(q) if result.mode != Mode.HOMING else (0.0, 0.0)
        plant.advance(np.asarray(tilt) + offset_tilt, DT)
        if i * DT >= 8.0:
            errors.append(np.linalg.norm(plant.p - pipe.reference.sample(i * DT + DT - pipe.t_engaged).p))
    return float(np.sqrt(np.mean(np.square(errors)))), pipe


@pytest.mark.parametrize("controller", ["pid", "mpc"])
def test_both_controllers_adapt_to_a_weaker_plant_and_a_tilted_plate(controller):
    fixed, _ = _circle_error_on_a_half_gain_plant(controller, adapt=False)
    adapted, pipe = _circle_error_on_a_half_gain_plant(controller, adapt=True)
    assert abs(pipe.plant.k_g - 0.5 * K_G) < 0.15 * K_G
    assert adapted < 0.6 * fixed


def test_a_fresh_engagement_leads_the_reference_in_from_the_ball():
    register_tilt_law("constant_for_lead_in", _ConstantLaw)
    try:
        pipe = _pipeline("constant_for_lead_in", engage_accel_m_s2=0.2, latency_compensation=False)
        ball = (0.06, -0.045)                               # 75 mm from the centre
        lead_s = math.sqrt(6.0 * 0.075 / 0.2)               # 1.5 s: 6 d / T^2 = 0.2 m/s^2
        q = np.array(LEVEL_HOME)
        for i in range(int((lead_s + 1.0) / DT)):
            q = pipe.step(i * DT, _observe(DelayedPlant(x0=ball)), q).q_cmd
        refs = [ctx.ref for ctx in pipe.law.contexts]
        np.testing.assert_allclose(refs[0].p, ball, atol=1e-9)        # starts at the ball, at rest
        np.testing.assert_allclose(refs[0].v, 0.0, atol=1e-9)
        assert max(np.linalg.norm(r.a) for r in refs) <= 0.2 + 1e-9
        steps = [np.linalg.norm(b.p - a.p) for a, b in zip(refs, refs[1:])]
        assert max(steps) < 0.2 * DT                        # no jump on the way
        np.testing.assert_allclose(refs[-1].p, (0.0, 0.0), atol=1e-12)   # then the reference itself
        assert tuple(pipe.reference.sample(0.0).p) == (0.0, 0.0)         # which is unchanged
    finally:
        TILT_LAWS.pop("constant_for_lead_in")


def test_the_published_target_is_the_reference_at_the_tick_not_the_look_ahead():
    # the law aims a latency ahead (ref); /ball_reference, stamped with the tick's time,
    # carries the target at that time, or a ball on the circle would seem to trail it
    circle = Circle(0.1, 10.0)
    pipe = _pipeline("pid", reference=circle, engage_accel_m_s2=0.0, actuation_delay_s=0.05,
                     estimate_delay=False)
    plant = DelayedPlant(x0=(0.1, 0.0))
    q = np.array(LEVEL_HOME)
    engaged = []
    for i in range(int(3.0 / DT)):
        result = pipe.step(i * DT, _observe(plant), q)
        q = result.q_cmd
        plant.advance(pipe.kin.tilt_of(q) if result.mode != Mode.HOMING else (0.0, 0.0), DT)
        if result.mode == Mode.ENGAGED:
            engaged.append((i * DT, result))
        else:
            assert result.target_m is None
    assert engaged
    for now_s, result in engaged:
        t_s = now_s - pipe.t_engaged
        np.testing.assert_allclose(result.target_m, circle.sample(t_s).p, atol=1e-12)
        np.testing.assert_allclose(result.ref.p, circle.sample(t_s + 0.05).p, atol=1e-12)


@pytest.mark.parametrize("controller", ["pid", "mpc"])
def test_a_strong_plant_with_a_long_unknown_delay_is_not_thrown_at_engagement(controller):
    """Twice the model's k g and 0.18 s from command to plate (the arm's joints show it that
    late), the ball released 86 mm out: led in, it never rolls farther out than it started, and
    the tilt stays small while the delay and gain estimates fill; at once, full tilt throws it
    beyond its start before they have data."""
    def run(engage_accel_m_s2):
        pipe = _pipeline(controller, engage_accel_m_s2=engage_accel_m_s2)
        plant = DelayedPlant(x0=(0.07, -0.05), delay_s=0.18, k_g=2.0 * K_G)
        q = np.array(LEVEL_HOME)
        sent = deque([q.copy()] * int(round(0.18 / DT)))   # joint states: the command 0.18 s ago
        farthest, first_tilt = 0.0, 0.0
        for i in range(int(8.0 / DT)):
            result = pipe.step(i * DT, _observe(plant), sent[0])
            sent.append(result.q_cmd.copy())
            sent.popleft()
            tilt = pipe.kin.tilt_of(result.q_cmd) if result.mode != Mode.HOMING else (0.0, 0.0)
            plant.advance(tilt, DT)
            farthest = max(farthest, float(np.linalg.norm(plant.p)))
            if i * DT < 1.0:
                first_tilt = max(first_tilt, float(np.max(np.abs(result.u))))
        return farthest, first_tilt, float(np.linalg.norm(plant.p))

    farthest, first_tilt, final = run(0.2)
    assert farthest <= np.hypot(0.07, -0.05) + 1e-3 and first_tilt < 0.12 and final < 0.003
    farthest_at_once, first_tilt_at_once, _ = run(0.0)
    assert farthest_at_once > farthest + 0.02 and first_tilt_at_once == pytest.approx(0.15)


def test_plate_cmd_is_the_tilt_the_ball_feels_under_the_estimated_disturbance():
    # the tracker predicts the ball from /plate_cmd: under a disturbance d the ball accelerates
    # as under the tilt u - asin(d / k_g), not u
    pipe = _pipeline("pid")
    plant = DelayedPlant(x0=(0.02, 0.0))
    q_prev = np.array(LEVEL_HOME)
    result = None
    for i in range(25):
        result = pipe.step(i * DT, _observe(plant), q_prev)
        q_prev = result.q_cmd
    assert result.plate_cmd == result.u                 # no disturbance estimated
    pipe.plant.offset = np.array([0.1, -0.05])
    result = pipe.step(25 * DT, _observe(plant), q_prev)
    level = np.arcsin(pipe.plant.offset / pipe.plant.k_g)
    np.testing.assert_allclose(result.plate_cmd, np.array(result.u) - level, atol=1e-12)


def test_the_trackers_level_offset_is_cancelled_and_the_tilt_sent_as_commanded():
    # a tracker that estimates the disturbance (its filter sees the detections) gives it as a
    # plate-level offset: the controller cancels that tilt and tells the tracker the tilt itself
    pipe = _pipeline("pid")
    plant = DelayedPlant(x0=(0.0, 0.0))
    level = (0.03, -0.02)
    q_prev = np.array(LEVEL_HOME)
    result = None
    for i in range(25):
        result = pipe.step(i * DT, _observe(plant, level_offset_rad=level), q_prev)
        q_prev = result.q_cmd
    np.testing.assert_allclose(level_offset_rad(pipe.plant.offset, pipe.plant.k_g), level, atol=1e-12)
    assert result.plate_cmd == result.u
    np.testing.assert_allclose(result.u, level, atol=2e-3)   # the ball at the target: the offset is the tilt
