"""The whole tick (safety, prediction, controller, IK, shaping) on a plant driven by the
tilt the commanded joints actually produce."""
import math

import numpy as np
import pytest
from control_plant import DelayedPlant
from test_control_kinematics import LEVEL_HOME, UR_JOINTS, URDF

from ball_balance.control.kinematics import Chain, PlateKinematics, ShaperConfig
from ball_balance.control.pipeline import ControlPipeline, PipelineConfig
from ball_balance.control.references import Stationary
from ball_balance.control.safety import BallObservation, Mode

pytestmark = pytest.mark.skipif(not URDF.exists(), reason="robot description not in the tree yet")
DT = 0.02
STEP = 0.03


def _pipeline(controller, mode="wrist"):
    kin = PlateKinematics(Chain.from_urdf(URDF.read_text(), UR_JOINTS), LEVEL_HOME,
                          shaper=ShaperConfig(max_joint_step_rad=STEP), mode=mode)
    return ControlPipeline(PipelineConfig(controller=controller), kin, Stationary())


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
    pipe = _pipeline("pid")
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
