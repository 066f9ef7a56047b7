"""Joint limits: one saturation rule for controllers (JointLimiter) and the manager's stage
before write() (HandleLimiter); limit-less joints refused at load; clamps counted and logged."""
import logging
import math

import pytest
from cm_helpers import HOME, JOINTS, MOCK_UR, make_manager, run, spawn

from controller_manager_py.hardware_interface import JointLimits
from controller_manager_py.hardware_interface.urdf import DescriptionError, parse_control_resources
from controller_manager_py.manager.controller_manager import ControllerManager
from controller_manager_py.manager.introspection import introspection_entries
from controller_manager_py.manager.joint_limits import JointLimiter, limits_from_description
from controller_manager_py.manager.resource_manager import ResourceError

FORWARD = "position_controllers/JointGroupPositionController"
ARM = JointLimits(min_position=-1.0, max_position=1.0, max_velocity=2.0)


def test_position_beyond_the_range_is_clamped_counted_and_logged_once(caplog):
    limiter = JointLimiter(["j"], {"j": ARM}, logging.getLogger("t"), "fwd")
    limiter.reset([0.99])
    with caplog.at_level(logging.WARNING):
        for _ in range(5):
            assert limiter.limit_positions([50.0], 0.01) == [1.0]
    assert limiter.clamped == 5 and limiter.clamped_by_joint == {"j": 5} and limiter.last_limited == [True]
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 1 and "fwd: j position command 50 limited to 1" in lines[0]


def test_position_steps_are_limited_to_max_velocity_times_period():
    limiter = JointLimiter(["j"], {"j": ARM})
    limiter.reset([0.0])
    out = [limiter.limit_positions([0.9], 0.01)[0] for _ in range(3)]
    assert out == pytest.approx([0.02, 0.04, 0.06])
    assert limiter.clamped == 3


def test_acceleration_limit_ramps_the_velocity_up():
    lim = JointLimits(min_position=-10, max_position=10, max_velocity=5.0, max_acceleration=100.0)
    limiter = JointLimiter(["j"], {"j": lim})
    limiter.reset([0.0])
    steps = [limiter.limit_positions([5.0], 0.01)[0] for _ in range(3)]
    # velocity 1, 2, 3 rad/s after each 10 ms step
    assert steps == pytest.approx([0.01, 0.03, 0.06])


def test_commands_within_limits_pass_unchanged_and_nan_means_no_command():
    limiter = JointLimiter(["a", "b"], {"a": ARM, "b": ARM})
    limiter.reset([0.0, 0.0])
    assert limiter.limit_positions([0.01, math.nan], 0.01)[0] == 0.01
    assert math.isnan(limiter.limit_positions([0.01, math.nan], 0.01)[1])
    assert limiter.clamped == 0


def test_infinite_command_is_refused_and_the_previous_one_held():
    limiter = JointLimiter(["j"], {"j": ARM})
    limiter.reset([0.5])
    assert limiter.limit_positions([math.inf], 0.01) == [0.5]
    assert limiter.clamped == 1


def test_velocity_commands_are_clamped_to_max_velocity():
    limiter = JointLimiter(["j"], {"j": ARM})
    assert limiter.limit_velocities([-7.0], 0.01) == [-2.0]
    assert limiter.clamped == 1


def test_a_joint_without_limits_is_not_limited():
    limiter = JointLimiter(["free"], {})
    limiter.reset([0.0])
    assert limiter.limit_positions([50.0], 0.01) == [50.0]


def test_limits_from_description_reads_the_urdf_for_a_controller():
    limits = limits_from_description(MOCK_UR)
    assert limits["elbow_joint"].max_position == pytest.approx(math.pi)
    assert limits["wrist_1_joint"].max_velocity == 3.14


def test_acceleration_command_interface_max_sets_the_acceleration_limit():
    tag = '<command_interface name="position"/>'
    urdf = MOCK_UR.replace(tag, tag + '<command_interface name="acceleration"><param name="max">8</param>'
                                      '</command_interface>', 1)
    (info,) = parse_control_resources(urdf)
    assert info.limits["shoulder_pan_joint"].max_acceleration == 8.0
    assert not info.limits["elbow_joint"].has_acceleration_limits


def _without_limit(joint: str) -> str:
    start = MOCK_UR.index(f'<joint name="{joint}" type="revolute">')
    limit_start = MOCK_UR.index("<limit", start)
    limit_end = MOCK_UR.index("/>", limit_start) + 2
    return MOCK_UR[:limit_start] + MOCK_UR[limit_end:]


def test_revolute_joint_without_limit_is_refused_at_load_with_one_line():
    cm = ControllerManager(500)
    with pytest.raises(ResourceError) as error:
        cm.load_robot_description(_without_limit("elbow_joint"))
    message = str(error.value)
    assert "elbow_joint" in message and "no <limit>" in message and "allow_joints_without_limits" in message
    assert "\n" not in message
    with pytest.raises(DescriptionError):
        parse_control_resources(_without_limit("elbow_joint"))


def test_joint_without_limit_is_accepted_with_the_opt_out():
    cm = ControllerManager(500)
    cm.load_robot_description(_without_limit("elbow_joint"), require_limits=False)
    fwd = spawn(cm, "fwd", FORWARD, {"joints": JOINTS})
    fwd.slot.offer([*HOME[:2], 50.0, *HOME[3:]])
    run(cm, 1)
    assert cm.rm.command_interfaces["elbow_joint/position"].value == 50.0


def test_joint_without_limit_but_limits_disabled_in_its_block_is_accepted():
    tag = '<joint name="elbow_joint">\n'
    urdf = _without_limit("elbow_joint").replace(tag, tag + '      <limits enable="false"/>\n')
    ControllerManager(500).load_robot_description(urdf)


def test_forward_command_at_50_rad_is_clamped_before_write_and_counted():
    cm = make_manager()
    fwd = spawn(cm, "fwd", FORWARD, {"joints": JOINTS})
    fwd.slot.offer([*HOME[:2], 50.0, *HOME[3:]])
    run(cm, 2000)
    comp = cm.rm.components["mock_ur"]
    assert cm.rm.state_interfaces["elbow_joint/position"].value == pytest.approx(math.pi)
    assert comp.limiter.clamped == 2000
    assert dict(introspection_entries(cm))["mock_ur.limited_commands"]() == 2000.0


def test_a_command_within_every_limit_is_passed_unchanged_and_not_counted():
    """previous + ((p - previous) / dt) * dt differs from p in the last bits (a joint moving
    toward zero shows it at once): an unsaturated step must return p itself, or rounding shows
    up as clamps in /diagnostics."""
    from controller_manager_py.manager.joint_limits import JointLimiter, JointLimits

    limiter = JointLimiter(["j"], {"j": JointLimits(min_position=-3.0, max_position=3.0, max_velocity=3.14)})
    limiter.reset([0.004])
    for k in range(1, 200):
        desired = 0.004 * (1.0 - k / 100.0) + 3.7e-15  # through zero, 2 mm per 2 ms = 1 rad/s
        assert limiter.limit_positions([desired], 0.002) == [desired]
    assert limiter.clamped == 0
