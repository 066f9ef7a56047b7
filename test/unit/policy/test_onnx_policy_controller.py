"""The generic ONNX policy controller inside the controller manager (mock UR arm, synthetic
time): commands from the model, async inference that never holds the loop, holds on bad data."""
import threading
from pathlib import Path

import numpy as np
import pytest

from controller_manager_py.manager.controller_manager import ControllerError, ControllerManager
from controller_manager_py.manager.introspection import statistics_entries

ROOT = Path(__file__).resolve().parents[3]
MODEL = Path(__file__).resolve().parent / "data" / "absolute_joint.onnx"
PLUGIN = "controller_manager_py.controllers.onnx_policy:OnnxPolicyController"
JOINT = "shoulder_pan_joint/position"
RATE = 100


def manager():
    cm = ControllerManager(RATE)
    cm.load_robot_description((ROOT / "config" / "mock_ur.urdf").read_text())
    return cm


def params(**kw):
    values = dict(model_path=str(MODEL), state_interfaces=[JOINT], inputs=["target"], command_interfaces=[JOINT],
                  blend_s=0.0, async_inference=False)
    values.update(kw)
    return values


def spawn(cm, **kw):
    cm.load_controller("policy", PLUGIN, params(**kw))
    cm.configure_controller("policy")
    cm.switch_controller(["policy"], [], 2)
    return cm.controllers["policy"].c


class Clock:
    def __init__(self, cm):
        self.cm, self.t = cm, 0.0

    def run(self, cycles):
        for _ in range(cycles):
            self.t += 1.0 / RATE
            self.cm.cycle(self.t, 1.0 / RATE)


def expected_command(ctrl, position, target, previous_target):
    action = ctrl.runner.infer([position, target, previous_target])
    return float(ctrl.runner.command(action)[0])


def test_commands_the_models_output_from_its_named_sources():
    cm = manager()
    ctrl = spawn(cm)
    clock = Clock(cm)
    ctrl.set_inputs([0.2])
    clock.run(1)
    ctrl.set_inputs([0.3])
    position = cm.rm.command_interfaces[JOINT].value    # the mock arm reads back what it was told
    clock.run(1)
    assert cm.rm.command_interfaces[JOINT].value == pytest.approx(expected_command(ctrl, position, 0.3, 0.2), abs=1e-6)
    assert ctrl.inferences == 2 and ctrl.missed_inferences == 0


def test_slow_inference_never_holds_the_loop_and_missed_inferences_reuse_the_last_action():
    cm = manager()
    ctrl = spawn(cm, async_inference=True)
    clock = Clock(cm)
    ctrl.set_inputs([0.1])
    clock.run(1)
    assert ctrl._worker.wait_idle(10.0)
    clock.run(1)                      # the first action is in use
    first = cm.rm.command_interfaces[JOINT].value
    release = threading.Event()
    session = ctrl.runner.session

    class SlowSession:
        """An artificially slow model: every inference waits for the test to let it finish."""

        def run(self, outputs, feed):
            release.wait(30.0)
            return session.run(outputs, feed)

    ctrl.runner.session = SlowSession()
    ctrl.set_inputs([0.5])
    clock.run(20)                     # 20 cycles while one inference hangs: the loop went on
    assert ctrl._worker.busy
    assert ctrl.missed_inferences >= 18
    assert cm.rm.command_interfaces[JOINT].value == first     # the last action, reused
    release.set()
    assert ctrl._worker.wait_idle(30.0)
    clock.run(1)
    assert cm.rm.command_interfaces[JOINT].value != first
    assert ctrl.inference_stats.sample_count >= 2
    names = [n for n, _ in statistics_entries(cm)]
    assert "policy.inference_time/average" in names and "policy.data_age/max" in names
    cm.switch_controller([], ["policy"], 2)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_observation_never_reaches_the_command_interface(bad):
    cm = manager()
    ctrl = spawn(cm)
    clock = Clock(cm)
    ctrl.set_inputs([0.2])
    clock.run(3)
    held = cm.rm.command_interfaces[JOINT].value
    ctrl.set_inputs([bad])
    clock.run(5)
    assert cm.rm.command_interfaces[JOINT].value == held
    assert ctrl.refused_observations == 5
    ctrl.set_inputs([0.2])
    clock.run(1)
    assert ctrl.refused_observations == 5


def test_command_is_rate_limited():
    cm = manager()
    ctrl = spawn(cm, max_rate=0.02)
    clock = Clock(cm)
    start = cm.rm.state_interfaces[JOINT].value
    ctrl.set_inputs([0.9])
    values = []
    for _ in range(20):
        clock.run(1)
        values.append(cm.rm.command_interfaces[JOINT].value)
    steps = np.abs(np.diff([start] + values))
    assert np.all(steps <= 0.02 / RATE + 1e-12)
    assert steps.max() == pytest.approx(0.02 / RATE)


def test_policy_blends_in_from_the_held_command_after_activation():
    unblended = manager()
    free = spawn(unblended)
    blended = manager()
    ctrl = spawn(blended, blend_s=1.0)
    start = blended.rm.state_interfaces[JOINT].value
    for cm, c in ((unblended, free), (blended, ctrl)):
        c.set_inputs([0.9])
        Clock(cm).run(1)
    full = unblended.rm.command_interfaces[JOINT].value - start
    first = blended.rm.command_interfaces[JOINT].value - start
    assert abs(full) > 1e-4
    assert first == pytest.approx(full / RATE, rel=1e-6)


def test_model_that_does_not_fit_the_parameters_is_refused_at_configure():
    cm = manager()
    with pytest.raises(ControllerError, match="on_configure failed"):
        spawn(cm, inputs=[""])         # the model reads 'target': no such source
    cm2 = manager()
    with pytest.raises(ControllerError, match="on_configure failed"):
        spawn(cm2, command_interfaces=[JOINT, "shoulder_lift_joint/position"])
    cm3 = manager()
    with pytest.raises(ControllerError, match="on_configure failed"):
        spawn(cm3, model_path=str(MODEL.parent / "no_metadata.onnx"))


def test_refusal_reason_is_one_line_naming_the_missing_source(caplog):
    cm = manager()
    with caplog.at_level("ERROR"), pytest.raises(ControllerError):
        spawn(cm, inputs=[""])
    lines = [r.getMessage() for r in caplog.records if "no source" in r.getMessage()]
    assert len(lines) == 1 and "'target'" in lines[0] and "\n" not in lines[0]


def test_inferences_keep_the_models_rate_in_a_loop_that_is_not_a_whole_multiple_of_it():
    """A 100 Hz model in a 250 Hz loop: an inference every 2 or 3 cycles, 100 per second (as a
    60 Hz model at the manager's 500 Hz), not one every 3 cycles (83 per second)."""
    loop_hz = 250
    cm = ControllerManager(loop_hz)
    cm.load_robot_description((ROOT / "config" / "mock_ur.urdf").read_text())
    ctrl = spawn(cm)
    ctrl.set_inputs([0.2])
    t = 0.0
    for _ in range(2 * loop_hz):
        t += 1.0 / loop_hz
        cm.cycle(t, 1.0 / loop_hz)
    assert abs(ctrl.inferences - 2 * 100) <= 1
