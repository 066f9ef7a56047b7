"""The ball balance controller inside the controller manager (mock UR arm with the plate, synthetic
time, no ROS): the learned policy tilts the plate against the ball through the six position
command interfaces; bad ball states and a model that does not fit never reach the arm."""
import math
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from ball_balance.control.safety import Mode
from ball_balance.controllers.ball_balance_controller import NODE_ONLY, BallSample
from ball_balance.robot import JOINT_NAMES, robot_description
from controller_manager_py.manager.controller_manager import ControllerError, ControllerManager

ROOT = Path(__file__).resolve().parents[3]
PLUGIN = "ball_balance_controllers/BallBalanceController"
MANAGER_HZ = 500
COMMANDS = [f"{j}/position" for j in JOINT_NAMES]


def section(path: str, name: str) -> dict:
    values = yaml.safe_load((ROOT / path).read_text())[name]["ros__parameters"]
    return {k: v for k, v in values.items() if k not in NODE_ONLY}


def policy_values(**kw) -> dict:
    """What config/ur_controllers_policy.yaml runs (the policy's trained values), the step inline."""
    values = section("config/ur_controllers_policy.yaml", "ball_balance_controller")
    values.update(is_async=False, async_step=False)
    values.update(kw)
    return values


def loaded(robot_description_xml: str = "", **kw) -> ControllerManager:
    """A manager on the mock arm (or the given description) with the controller loaded as "ball"."""
    cm = ControllerManager(MANAGER_HZ)
    cm.load_robot_description(robot_description_xml or robot_description("mock"))
    cm.load_controller("ball", PLUGIN, policy_values(**kw))
    return cm


CONTROL_HZ = policy_values()["control_rate_hz"]   # 60: not a whole divisor of the manager's rate


def spawn(**kw):
    cm = loaded(**kw)
    cm.configure_controller("ball")
    cm.switch_controller(["ball"], [], 2)
    return cm, cm.controllers["ball"].c


class Run:
    """Synthetic time; a fresh ball state offered before every control step (a camera at the control rate)."""

    def __init__(self, cm, ctrl):
        self.cm, self.ctrl, self.t = cm, ctrl, 0.0
        self.offered = 0

    def run(self, seconds: float, ball=None):
        for _ in range(int(round(seconds * MANAGER_HZ))):
            self.t += 1.0 / MANAGER_HZ
            frame = math.floor(self.t * CONTROL_HZ + 1e-9)
            if ball is not None and frame != math.floor((self.t - 1.0 / MANAGER_HZ) * CONTROL_HZ + 1e-9):
                self.ctrl.offer_ball_state(BallSample(*ball, self.t), self.t)
                self.offered += 1
            self.cm.cycle(self.t, 1.0 / MANAGER_HZ)

    def commands(self):
        return np.array([self.cm.rm.command_interfaces[name].value for name in COMMANDS])


def test_the_policy_tilts_the_plate_to_roll_the_ball_back_to_the_centre():
    cm, ctrl = spawn()
    run = Run(cm, ctrl)
    run.run(1.0)                                         # homing, then ready: no ball yet
    assert ctrl.mode == Mode.READY
    run.run(1.0, ball=(0.06, -0.04, 0.0, 0.0, True, 4))   # the ball sits off centre, +x and -y
    assert ctrl.mode == Mode.ENGAGED
    u_x, u_y = ctrl.kinematics.tilt_of(run.commands())
    # positive u drives the ball toward negative x / y: the plate leans the ball back to the centre
    assert u_x > 0.005 and u_y < -0.003
    assert ctrl.pipeline.law.inferences > 0 and ctrl.pipeline.refused_count == 0


def test_a_non_finite_ball_state_never_reaches_the_arm_it_is_held_and_counted():
    cm, ctrl = spawn()
    run = Run(cm, ctrl)
    run.run(1.0)
    run.run(1.0, ball=(0.06, -0.04, 0.0, 0.0, True, 4))
    held = run.commands()
    good = run.offered
    run.run(0.1, ball=(math.nan, 0.0, 0.0, 0.0, True, 4))   # 6 NaN states in a row
    run.run(0.1, ball=(0.0, 0.0, math.inf, 0.0, True, 4))
    bad = run.offered - good
    assert bad >= 10
    assert ctrl.refusals["non_finite"] == bad and ctrl.refused_ball_states == bad
    assert ctrl._ball.x == pytest.approx(0.06)              # the good state is still the one in use
    commands = run.commands()
    assert np.all(np.isfinite(commands))
    assert np.max(np.abs(commands - held)) < 0.1            # the arm stayed where it was (shaping steps)
    counters = dict((name, getter()) for name, getter in ctrl.introspection)
    assert counters["refused_ball_states_non_finite"] == bad   # reaches /diagnostics (refused_*)
    run.run(1.0)                                            # no state at all: holding, then home
    assert ctrl.mode in (Mode.HOLDING, Mode.RETURNING, Mode.READY)
    assert np.all(np.isfinite(run.commands()))


def test_reactivation_starts_over_from_homing_at_the_measured_joints():
    cm, ctrl = spawn()
    run = Run(cm, ctrl)
    run.run(1.0)
    run.run(1.0, ball=(0.06, -0.04, 0.0, 0.0, True, 4))
    cm.switch_controller([], ["ball"], 2)
    cm.switch_controller(["ball"], [], 2)
    run.run(0.02)
    assert ctrl.mode == Mode.HOMING


@pytest.mark.parametrize("law", ["pid", "mpc"])
def test_the_pid_and_the_mpc_run_in_the_manager_as_well(law):
    cm, ctrl = spawn(tilt_law=law)
    run = Run(cm, ctrl)
    run.run(1.0)
    run.run(1.0, ball=(0.06, -0.04, 0.0, 0.0, True, 4))
    assert ctrl.mode == Mode.ENGAGED
    u_x, u_y = ctrl.kinematics.tilt_of(run.commands())
    assert u_x > 0.0 and u_y < 0.0


def test_a_model_trained_on_another_pid_is_refused_at_configure_with_one_line(caplog):
    cm = loaded(kp=1.0)
    with pytest.raises(ControllerError, match="on_configure failed"):
        cm.configure_controller("ball")
    assert any("trained on a different PID (kp" in r.getMessage() for r in caplog.records)


def test_a_robot_description_without_the_plate_is_refused_at_configure(caplog):
    cm = loaded((ROOT / "config" / "mock_ur.urdf").read_text())
    with pytest.raises(ControllerError):
        cm.configure_controller("ball")
    assert any("plate_center" in r.getMessage() for r in caplog.records)


def test_with_async_step_a_slow_step_never_holds_up_the_loop_it_is_missed_and_counted():
    cm, ctrl = spawn(async_step=True)
    tilt = ctrl.pipeline.law.tilt

    def slow_tilt(ctx):
        time.sleep(0.05)                 # a policy far slower than the 20 ms control period
        return tilt(ctx)
    ctrl.pipeline.law.tilt = slow_tilt
    t = 0.0
    for k in range(1500):
        t += 1.0 / MANAGER_HZ
        if k % 10 == 0 and t > 0.5:
            ctrl.offer_ball_state(BallSample(0.06, -0.04, 0.0, 0.0, True, 4, t), t)
        cm.cycle(t, 1.0 / MANAGER_HZ)
        time.sleep(0.0005)               # (a paced loop: the worker gets the interpreter)
    ctrl._worker.wait_idle()
    # update() did not wait: steps came due while the slow one ran, were missed and counted
    assert ctrl.missed_steps > 0 and ctrl._worker.runs > 0
    counters = dict((name, getter()) for name, getter in ctrl.introspection)
    assert counters["missed_steps"] == float(ctrl.missed_steps)   # reaches /diagnostics (missed_*)
    assert ctrl.mode == Mode.ENGAGED and ctrl.pipeline.law.inferences > 0
    assert np.all(np.isfinite(Run(cm, ctrl).commands()))
    cm.switch_controller([], ["ball"], 2)   # deactivation stops the worker
    assert ctrl._worker is None


def test_steps_keep_the_control_rate_on_an_update_rate_that_is_not_a_whole_multiple_of_it():
    """60 Hz steps in the 500 Hz manager: each at the first update at or after its time (8 or 9
    updates apart), 60 per second, never drifting (the first step comes half a period after
    the start, as after any gap)."""
    cm, ctrl = spawn()
    assert MANAGER_HZ % CONTROL_HZ != 0
    steps = []
    step = ctrl._step

    def counted(time_s, period):
        steps.append(time_s)
        return step(time_s, period)
    ctrl._step = counted
    Run(cm, ctrl).run(2.0)
    gaps = np.diff(steps)[1:]
    assert abs(len(steps) - 2.0 * CONTROL_HZ) <= 1
    assert np.all(gaps > 1.0 / CONTROL_HZ - 1.0 / MANAGER_HZ - 1e-9)
    assert np.all(gaps < 1.0 / CONTROL_HZ + 1.0 / MANAGER_HZ + 1e-9)
    assert steps[-1] - steps[1] == pytest.approx((len(steps) - 2) / CONTROL_HZ, abs=1.0 / MANAGER_HZ)


def test_an_update_rate_below_the_control_rate_is_refused_at_configure(caplog):
    cm = loaded(update_rate=int(CONTROL_HZ // 2))
    with pytest.raises(ControllerError, match="on_configure failed"):
        cm.configure_controller("ball")
    assert any("must be at least control_rate_hz" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize("ramp", [True, False])
def test_the_command_ramps_across_each_control_period_instead_of_jumping_at_each_step(ramp):
    """command_ramp: between two steps the written joint command moves in equal parts at every
    update (8-9 per 60 Hz step at 500 Hz); without it the whole change comes at the step's
    update and the command then stands still until the next step (a staircase)."""
    cm, ctrl = spawn(command_ramp=ramp)
    run = Run(cm, ctrl)
    run.run(1.0)
    run.run(1.0, ball=(0.06, -0.04, 0.0, 0.0, True, 4))
    commands = []
    for _ in range(int(0.5 * MANAGER_HZ)):
        run.run(1.0 / MANAGER_HZ, ball=(0.06, -0.04, 0.0, 0.0, True, 4))
        commands.append(run.commands())
    per_update = np.max(np.abs(np.diff(commands, axis=0)), axis=1)
    moving = per_update > 1e-9
    assert ctrl.mode == Mode.ENGAGED and per_update.max() > 1e-5
    if ramp:
        assert moving.mean() > 0.9                 # the command moves at (nearly) every update
    else:
        assert moving.mean() < 0.2                 # once per step: about 60 of 500 updates
