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
