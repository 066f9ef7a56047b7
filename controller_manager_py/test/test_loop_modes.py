"""Loop modes: switching timing (between cycles, activate_asap, timeout), async hardware,
simulated clock, hardware-driven pacing, AUTO strictness, hardware state changes."""
import os
import threading
import time

import pytest
from cm_helpers import JOINTS, MOCK_UR, make_manager, run, spawn

from controller_manager_py.hardware_interface import State
from controller_manager_py.hardware_interface.types import return_type
from controller_manager_py.manager.async_handler import AsyncHandler
from controller_manager_py.manager.loop import ControlLoop
from controller_manager_py.manager.switching import AUTO, FORCE_AUTO, STRICT, SwitchError

FORWARD = "position_controllers/JointGroupPositionController"
COUNTING = "cm_helpers:CountingController"


def switch_in_background(cm, *args, **kwargs):
    outcome = {}

    def target():
        try:
            outcome["plan"] = cm.switch_controller(*args, **kwargs)
        except SwitchError as error:
            outcome["error"] = error
    thread = threading.Thread(target=target)
    thread.start()
    time.sleep(0.1)  # the request is now pending
    return thread, outcome


def test_switch_waits_for_the_cycle_boundary_and_asap_false_waits_one_more_cycle():
    cm = make_manager()
    spawn(cm, "fwd", FORWARD, {"joints": JOINTS}, activate=False)
    cm.loop_running = True  # cycles are driven by hand below
    thread, outcome = switch_in_background(cm, ["fwd"], [], STRICT, activate_asap=False, timeout=5.0)
    assert cm.controllers["fwd"].state == State.INACTIVE  # nothing happens between cycles
    run(cm, 1)
    assert cm.controllers["fwd"].state == State.INACTIVE  # hardware switched modes: one read first
    assert thread.is_alive()  # the caller returns only when the controllers are active
    run(cm, 1)
    thread.join(2)
    assert "plan" in outcome and cm.controllers["fwd"].state == State.ACTIVE


def test_switch_times_out_when_no_cycle_runs_and_is_not_applied_later():
    cm = make_manager()
    spawn(cm, "c", COUNTING, activate=False)
    cm.loop_running = True
    with pytest.raises(SwitchError, match="not performed within 0.2 s"):
        cm.switch_controller(["c"], [], STRICT, timeout=0.2)
    run(cm, 2)
    assert cm.controllers["c"].state == State.INACTIVE


def test_auto_activates_the_chained_controller_and_force_auto_takes_over_claims():
    cm = make_manager()
    spawn(cm, "pass", "chained_controllers/PassthroughController", {"joints": JOINTS}, activate=False)
    spawn(cm, "head", "forward_command_controller/ForwardCommandController",
          {"joints": [f"pass/{j}" for j in JOINTS]}, activate=False)
    with pytest.raises(SwitchError, match="needs controller 'pass' active"):
        cm.switch_controller(["head"], [], STRICT)
    cm.switch_controller(["head"], [], AUTO)
    assert cm.controllers["pass"].state == State.ACTIVE and cm.controllers["head"].state == State.ACTIVE
    spawn(cm, "fwd", FORWARD, {"joints": JOINTS}, activate=False)
    cm.switch_controller(["fwd"], [], FORCE_AUTO)
    assert cm.controllers["fwd"].state == State.ACTIVE
    assert cm.controllers["pass"].state == State.INACTIVE and cm.controllers["head"].state == State.INACTIVE


def test_deactivating_hardware_deactivates_the_controllers_using_it():
    cm = make_manager()
    spawn(cm, "fwd", FORWARD, {"joints": JOINTS})
    assert cm.set_hardware_component_state("mock_ur", State.INACTIVE) == State.INACTIVE
    assert cm.controllers["fwd"].state == State.INACTIVE
    with pytest.raises(SwitchError):  # its command interfaces are there, but not writable any more
        cm.set_hardware_component_state("mock_ur", State.UNCONFIGURED)
        cm.switch_controller(["fwd"], [], STRICT)


@pytest.mark.parametrize("policy", ["synchronized", "detached"])
def test_async_hardware_reads_and_writes_in_its_own_thread(policy):
    urdf = MOCK_UR.replace('<ros2_control name="mock_ur" type="system">',
                           '<ros2_control name="mock_ur" type="system" is_async="true" rw_rate="100">').replace(
        "</hardware>", f'<properties><async scheduling_policy="{policy}"/></properties></hardware>')
    cm = make_manager(rate=100, urdf=urdf)
    comp = cm.rm.components["mock_ur"]
    assert comp.async_handler is not None
    fwd = spawn(cm, "fwd", FORWARD, {"joints": JOINTS})
    fwd.slot.offer([0.01] * 6)
    deadline = time.monotonic() + 3
    t = 0.0
    while cm.rm.state_interfaces["elbow_joint/position"].value != 0.01 and time.monotonic() < deadline:
        t = run(cm, 1, start=t)
        time.sleep(0.01)
    assert cm.rm.state_interfaces["elbow_joint/position"].value == 0.01
    assert comp.async_handler.runs > 0 and comp.data_age(cm.now()) < 1.0
    cm.shutdown()
    assert comp.async_handler is None


def test_simulated_clock_from_the_hardware_drives_controller_time():
    cm = make_manager(urdf=MOCK_UR.replace("mock_components/GenericSystem", "cm_helpers:SimClockSystem"))
    jsb = spawn(cm, "jsb", "joint_state_broadcaster/JointStateBroadcaster")
    loop = ControlLoop(cm)
    loop.start()
    try:
        deadline = time.monotonic() + 3
        while loop.cycles < 20 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        loop.stop()
    assert jsb.msg.header.stamp.sec == 1000  # simulated seconds, not the wall clock
    assert cm.now() == pytest.approx(1000.0 + 0.001 * loop.cycles, abs=0.002)


def test_hardware_driven_mode_lets_a_blocking_read_set_the_pace():
    cm = make_manager(rate=500, urdf=MOCK_UR.replace("mock_components/GenericSystem", "cm_helpers:BlockingSystem"))
    loop = ControlLoop(cm, expect_blocking_read_write=True)
    started = time.monotonic()
    loop.start()
    deadline = started + 30.0  # a deadline, not a duration: a busy machine only slows it
    while loop.cycles < 10 and time.monotonic() < deadline:
        time.sleep(0.01)
    loop.stop()
    elapsed = time.monotonic() - started
    assert loop.cycles >= 10
    # each cycle blocks 10 ms in read(): ~100 Hz at most, never the manager's 500 Hz
    assert loop.cycles <= elapsed / 0.010 + 1
    assert loop.overruns == 0


def test_hardware_rw_rate_reads_every_nth_cycle():
    urdf = MOCK_UR.replace('type="system">', 'type="system" rw_rate="100">', 1)
    cm = make_manager(rate=500, urdf=urdf)
    comp = cm.rm.components["mock_ur"]
    run(cm, 50)
    assert comp.divisor == 5 and comp.read_stats.execution_time.sample_count == 10


def test_loop_and_async_threads_run_on_the_cpus_they_are_pinned_to():
    cpus = sorted(os.sched_getaffinity(0))
    cm = make_manager()
    loop = ControlLoop(cm, cpu_affinity=[cpus[-1]])
    loop.start()
    handler = AsyncHandler("pinned", lambda time, period: return_type.OK, affinity=[cpus[0]])
    try:
        deadline = time.monotonic() + 3
        while (loop.cycles < 5 or handler._thread.native_id is None) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert os.sched_getaffinity(loop._thread.native_id) == {cpus[-1]}
        assert os.sched_getaffinity(handler._thread.native_id) == {cpus[0]}
    finally:
        loop.stop()
        handler.stop()
