"""Controllers through their lifecycle against the mock arm, with synthetic time."""
import math

import pytest
from cm_helpers import HOME, JOINTS, make_manager, positions, run, spawn

from controller_manager_py.hardware_interface import State
from controller_manager_py.manager.controller_manager import ControllerError, ControllerManager

FORWARD = "position_controllers/JointGroupPositionController"
JSB = "joint_state_broadcaster/JointStateBroadcaster"


def test_load_configure_activate_deactivate_cleanup_unload():
    cm = make_manager()
    cm.load_controller("fwd", FORWARD, {"joints": JOINTS})
    assert cm.controllers["fwd"].state == State.UNCONFIGURED
    cm.configure_controller("fwd")
    assert cm.controllers["fwd"].state == State.INACTIVE
    cm.switch_controller(["fwd"], [])
    assert cm.controllers["fwd"].state == State.ACTIVE
    assert cm.rm.claimed == {f"{j}/position": "fwd" for j in JOINTS}
    with pytest.raises(ControllerError, match="active; deactivate it before unloading"):
        cm.unload_controller("fwd")
    cm.switch_controller([], ["fwd"])
    assert cm.rm.claimed == {} and cm.controllers["fwd"].state == State.INACTIVE
    cm.cleanup_controller("fwd")
    assert cm.controllers["fwd"].state == State.UNCONFIGURED
    cm.unload_controller("fwd")
    assert "fwd" not in cm.controllers


def test_every_visible_change_calls_on_change_once():
    """The node publishes ~/activity and new statistics names when told, not by polling."""
    cm = make_manager()
    versions = []
    cm.on_change = lambda: versions.append(cm.version)
    cm.load_controller("fwd", FORWARD, {"joints": JOINTS})
    cm.configure_controller("fwd")
    assert len(versions) == 2
    cm.switch_controller(["fwd"], [])
    cm.switch_controller([], ["fwd"])
    cm.cleanup_controller("fwd")
    cm.unload_controller("fwd")
    assert len(versions) >= 6 and versions == sorted(set(versions)) and versions[-1] == cm.version
    run(cm, 10)   # cycles without a change tell nobody
    assert versions[-1] == cm.version


def test_unknown_controller_type_and_duplicate_load_are_refused():
    cm = make_manager()
    with pytest.raises(ControllerError, match="unknown controller plugin 'acme/Magic'"):
        cm.load_controller("x", "acme/Magic")
    spawn(cm, "fwd", FORWARD, {"joints": JOINTS}, activate=False)
    with pytest.raises(ControllerError, match="already loaded"):
        cm.load_controller("fwd", FORWARD)


def test_unknown_interface_in_controller_config_fails_configure_clearly():
    cm = make_manager()
    cm.load_controller("fwd", FORWARD, {"joints": ["elbow_joint", "knee_joint"]})
    with pytest.raises(ControllerError, match=r"unknown command interface\(s\) \['knee_joint/position'\]"):
        cm.configure_controller("fwd")
    assert cm.controllers["fwd"].state == State.UNCONFIGURED


def test_bad_parameter_value_names_the_parameter():
    cm = make_manager()
    cm.load_controller("fwd", FORWARD, {"joints": []})
    with pytest.raises(ControllerError, match="parameter 'joints'"):
        cm.configure_controller("fwd")


def test_forward_commands_reach_the_mock_and_bad_commands_are_refused_and_counted():
    cm = make_manager()
    fwd = spawn(cm, "fwd", FORWARD, {"joints": JOINTS})
    run(cm, 3)
    assert positions(cm) == HOME  # no command yet: nothing written
    target = [0.1, -1.5, 1.5, -1.5, 1.5, 0.2]
    assert fwd.slot.offer(target)
    run(cm, 200)  # velocity limit 3.14 rad/s: reached within 0.4 s
    assert positions(cm) == pytest.approx(target)
    assert not fwd.slot.offer([0.0] * 5)
    assert not fwd.slot.offer([math.nan] + target[1:])
    assert not fwd.slot.offer([math.inf] + target[1:])
    run(cm, 5)
    assert positions(cm) == pytest.approx(target)  # last good command kept
    assert fwd.slot.refused == 3


def commands(cm):
    return [cm.rm.command_interfaces[f"{j}/position"].value for j in JOINTS]


def test_command_ramp_writes_a_staircase_of_commands_as_ramps_reached_by_the_next_one():
    cm = make_manager()   # 500 Hz: commands every 10 cycles are a 50 Hz staircase
    fwd = spawn(cm, "fwd", FORWARD, {"joints": JOINTS, "command_ramp": True})
    t = 0.0
    for k in range(1, 6):     # the interval between commands is learnt from their arrivals
        fwd.slot.offer([HOME[0] + 0.01 * k] + HOME[1:])
        t = run(cm, 10, start=t)
    assert commands(cm)[0] == pytest.approx(HOME[0] + 0.05)    # each reached before the next
    fwd.slot.offer([HOME[0] + 0.06] + HOME[1:])
    written = []
    for _ in range(10):
        t = run(cm, 1, start=t)
        written.append(commands(cm)[0] - HOME[0])
    # a straight line from 0.05 to 0.06 over the 10 cycles, not one jump
    assert written == pytest.approx([0.05 + 0.001 * (i + 1) for i in range(10)], abs=1e-9)
    assert commands(cm)[1:] == pytest.approx(HOME[1:])


def test_command_ramp_is_bounded_and_starts_from_what_was_written():
    cm = make_manager()
    fwd = spawn(cm, "fwd", FORWARD, {"joints": JOINTS, "command_ramp": True, "command_ramp_max_s": 0.02})
    # (steps within the mock's velocity limit, 3.14 rad/s = 6.3 mrad per cycle, so none is clamped)
    fwd.slot.offer(HOME)      # the mock's commands start unset (NaN): the first is written as it is
    t = run(cm, 1)
    assert commands(cm) == pytest.approx(HOME)
    t = run(cm, 19, start=t)  # the next comes 40 ms later: the interval counts as 20 ms
    fwd.slot.offer([HOME[0] + 0.02] + HOME[1:])   # from what was written, over the 20 ms at most
    t = run(cm, 1, start=t)
    assert commands(cm)[0] == pytest.approx(HOME[0] + 0.002)
    t = run(cm, 9, start=t)
    assert commands(cm)[0] == pytest.approx(HOME[0] + 0.02)
    t = run(cm, 500, start=t)               # a second later: the interval counts as 20 ms at most
    fwd.slot.offer([HOME[0] + 0.04] + HOME[1:])
    t = run(cm, 5, start=t)
    assert commands(cm)[0] == pytest.approx(HOME[0] + 0.03)
    run(cm, 5, start=t)
    assert commands(cm)[0] == pytest.approx(HOME[0] + 0.04)


def test_reactivation_does_not_replay_a_stale_command():
    cm = make_manager()
    fwd = spawn(cm, "fwd", FORWARD, {"joints": JOINTS})
    fwd.slot.offer([0.3] + HOME[1:])
    cm.switch_controller([], ["fwd"])
    cm.switch_controller(["fwd"], [])
    assert fwd.slot.take() is None


def test_joint_state_broadcaster_reports_every_joint():
    cm = make_manager()
    jsb = spawn(cm, "jsb", JSB)
    run(cm, 2, start=10.0)
    assert list(jsb.msg.name) == JOINTS
    assert list(jsb.msg.position) == HOME and list(jsb.msg.velocity) == [0.0] * 6
    assert list(jsb.msg.effort) == []
    assert jsb.msg.header.stamp.sec == 10


def test_joint_limits_clamp_position_and_rate_and_flag_is_limited():
    cm = make_manager()
    fwd = spawn(cm, "fwd", FORWARD, {"joints": JOINTS})
    fwd.slot.offer([0.0, -1.5707963267948966, 5.0, -1.5707963267948966, 1.5707963267948966, 0.0])
    run(cm, 1)
    elbow = cm.rm.command_interfaces["elbow_joint/position"]
    assert elbow.is_limited and elbow.value == pytest.approx(HOME[2] + 3.14 / 500)
    run(cm, 1000)
    assert elbow.value == pytest.approx(math.pi)  # URDF upper limit
    assert not cm.rm.command_interfaces["shoulder_pan_joint/position"].is_limited


def test_limits_can_be_switched_off_per_joint_or_globally():
    from cm_helpers import MOCK_UR

    tag = '<joint name="elbow_joint">\n'
    urdf = MOCK_UR.replace(tag, tag + '      <limits enable="false"/>\n')
    assert '<limits enable="false"/>' in urdf
    for cm in (make_manager(urdf=urdf), make_manager_without_limits()):
        fwd = spawn(cm, "fwd", FORWARD, {"joints": JOINTS})
        fwd.slot.offer([0.0, -1.5707963267948966, 5.0, -1.5707963267948966, 1.5707963267948966, 0.0])
        run(cm, 1)
        assert cm.rm.command_interfaces["elbow_joint/position"].value == 5.0


def make_manager_without_limits():
    from cm_helpers import MOCK_UR

    cm = ControllerManager(500)
    cm.load_robot_description(MOCK_UR, enforce_command_limits=False)
    return cm


def test_joint_state_broadcaster_with_listed_joints_publishes_those_in_order():
    cm = make_manager()
    jsb = spawn(cm, "jsb", JSB, {"joints": ["elbow_joint", "shoulder_pan_joint"]})
    run(cm, 1)
    assert list(jsb.msg.name) == ["elbow_joint", "shoulder_pan_joint"]
    assert list(jsb.msg.position) == [HOME[2], HOME[0]]
