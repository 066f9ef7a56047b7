"""Switching strictness, claiming conflicts, rates, async, fallback, hardware errors, chaining."""
import time

import pytest
from cm_helpers import JOINTS, MOCK_UR, FlakySystem, make_manager, positions, run, spawn

from controller_manager_py.hardware_interface import State
from controller_manager_py.manager.switching import BEST_EFFORT, STRICT, SwitchError

FORWARD = "position_controllers/JointGroupPositionController"
COUNTING = "cm_helpers:CountingController"


def two_forward_controllers(cm):
    spawn(cm, "a", FORWARD, {"joints": JOINTS})
    spawn(cm, "b", FORWARD, {"joints": JOINTS[:2]}, activate=False)
    spawn(cm, "c", COUNTING, activate=False)


def test_second_claim_fails_strict_with_the_holder_named_and_changes_nothing():
    cm = make_manager()
    two_forward_controllers(cm)
    with pytest.raises(SwitchError, match="'shoulder_pan_joint/position' is already claimed by controller 'a'"):
        cm.switch_controller(["c", "b"], [], STRICT)
    assert cm.controllers["c"].state == State.INACTIVE and cm.controllers["b"].state == State.INACTIVE
    assert set(cm.rm.claimed.values()) == {"a"}


def test_best_effort_activates_what_it_can():
    cm = make_manager()
    two_forward_controllers(cm)
    plan = cm.switch_controller(["c", "b", "ghost"], [], BEST_EFFORT)
    assert cm.controllers["c"].state == State.ACTIVE and cm.controllers["b"].state == State.INACTIVE
    assert len(plan.messages) == 2


def test_swap_in_one_switch_moves_the_claim():
    cm = make_manager()
    two_forward_controllers(cm)
    cm.switch_controller(["b"], ["a"], STRICT)
    assert cm.rm.claimed == {f"{j}/position": "b" for j in JOINTS[:2]}


def test_strict_fails_on_unknown_or_inactive_names():
    cm = make_manager()
    two_forward_controllers(cm)
    with pytest.raises(SwitchError, match="'ghost': controller is not loaded"):
        cm.switch_controller(["ghost"], [], STRICT)
    with pytest.raises(SwitchError, match="'b': controller is inactive, not active"):
        cm.switch_controller([], ["b"], STRICT)


def test_update_rate_divisor_and_rounding():
    cm = make_manager(rate=500)
    spawn(cm, "slow", COUNTING, {"update_rate": 100})
    spawn(cm, "odd", COUNTING, {"update_rate": 300})  # not a divisor: 500 / round(500/300) = 250 Hz
    spawn(cm, "full", COUNTING)
    run(cm, 500)
    assert cm.controllers["slow"].c.calls == 100
    assert cm.controllers["odd"].c.calls == 250
    assert cm.controllers["full"].c.calls == 500
    assert cm.controllers["slow"].c.periods[-1] == pytest.approx(0.01)


def test_async_controller_skips_triggers_while_busy_and_counts_them():
    cm = make_manager(rate=100)
    slow = spawn(cm, "slow", COUNTING, {"is_async": True})
    slow.sleep_s = 5.0  # blocks until released
    t = run(cm, 1)
    time.sleep(0.05)
    run(cm, 10, start=t)
    handler = cm.controllers["slow"].async_handler
    assert slow.calls == 1 and handler.skipped == 10
    slow.release.set()
    assert handler.wait_idle(2.0)
    cm.switch_controller([], ["slow"])


def test_exception_in_update_deactivates_and_activates_the_fallback():
    cm = make_manager(config={"bad": {"fallback_controllers": ["safe"]}})
    bad = spawn(cm, "bad", COUNTING)
    spawn(cm, "safe", FORWARD, {"joints": JOINTS}, activate=False)
    run(cm, 3)
    bad.raise_error = True
    run(cm, 2)
    assert cm.controllers["bad"].state == State.INACTIVE
    assert cm.controllers["safe"].state == State.ACTIVE
    assert cm.controllers["bad"].update_errors == 1
    run(cm, 5)  # the loop keeps running


def test_hardware_read_error_deactivates_its_controllers():
    cm = make_manager(urdf=MOCK_UR.replace("mock_components/GenericSystem", "cm_helpers:FlakySystem"))
    spawn(cm, "fwd", FORWARD, {"joints": JOINTS})
    spawn(cm, "other", COUNTING)  # uses no interface of the arm: keeps running
    FlakySystem.fail_read = True
    try:
        run(cm, 1)
    finally:
        FlakySystem.fail_read = False
    assert cm.controllers["fwd"].state == State.INACTIVE
    assert cm.controllers["other"].state == State.ACTIVE
    assert cm.rm.components["mock_ur"].state == State.UNCONFIGURED
    run(cm, 3)


def test_chained_pair_forward_into_passthrough():
    cm = make_manager()
    spawn(cm, "pass", "chained_controllers/PassthroughController", {"joints": JOINTS})
    refs = [f"pass/{j}/position" for j in JOINTS]
    assert all(r in cm.rm.command_interfaces for r in refs)
    head = spawn(cm, "head", "forward_command_controller/ForwardCommandController",
                 {"joints": [f"pass/{j}" for j in JOINTS], "interface_name": "position"})
    assert cm.controllers["pass"].c.chained_mode
    assert [s.name for s in cm.ordered] == ["head", "pass"]
    target = [0.01, -1.56, 1.56, -1.56, 1.56, 0.01]
    head.slot.offer(target)
    run(cm, 20)
    assert positions(cm) == pytest.approx(target)
    with pytest.raises(SwitchError, match="reference interfaces are used by \\['head'\\]"):
        cm.switch_controller([], ["pass"], STRICT)
    cm.switch_controller([], ["head"], STRICT)
    assert not cm.controllers["pass"].c.chained_mode


def test_switch_with_a_running_loop_is_applied_between_cycles():
    from controller_manager_py.manager.loop import ControlLoop

    cm = make_manager(rate=200)
    spawn(cm, "c", COUNTING, activate=False)
    loop = ControlLoop(cm)
    loop.start()
    try:
        cm.switch_controller(["c"], [], STRICT, timeout=2.0)
        assert cm.controllers["c"].state == State.ACTIVE
        deadline = time.monotonic() + 2
        while cm.controllers["c"].c.calls < 5 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert cm.controllers["c"].c.calls >= 5
    finally:
        loop.stop()


def test_failed_activation_releases_claims_and_fails_a_strict_switch():
    cm = make_manager()
    spawn(cm, "r", "cm_helpers:RefusingController", activate=False)
    cm.controllers["r"].command_names = ["elbow_joint/position"]  # as if it asked for the elbow
    with pytest.raises(SwitchError, match=r"\['r'\] failed to activate"):
        cm.switch_controller(["r"], [], STRICT)
    assert cm.controllers["r"].state == State.INACTIVE and cm.rm.claimed == {}
    plan = cm.switch_controller(["r"], [], BEST_EFFORT)
    assert "failed to activate" in plan.messages[-1]
