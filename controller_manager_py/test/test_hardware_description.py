"""The <ros2_control> description: parsing, bad input, plugin lookup, the mock system."""
import logging

import pytest
from cm_helpers import HOME, JOINTS, MOCK_UR, make_manager, run, spawn

from controller_manager_py.hardware_interface import State, parse_control_resources
from controller_manager_py.hardware_interface.urdf import DescriptionError
from controller_manager_py.manager.controller_manager import ControllerManager
from controller_manager_py.manager.resource_manager import ResourceError


def test_mock_ur_description_lists_six_joints_with_limits_and_speed_scaling():
    (info,) = parse_control_resources(MOCK_UR)
    assert info.plugin == "mock_components/GenericSystem" and info.type == "system"
    assert [j.name for j in info.joints] == JOINTS
    assert info.limits["elbow_joint"].max_position == pytest.approx(3.14159, abs=1e-4)
    assert info.limits["wrist_3_joint"].max_velocity == 3.14
    assert info.gpios[0].state_interfaces[0].initial_value == 1.0


def test_async_properties_and_interface_params_are_parsed():
    xml = """<robot name="r"><ros2_control name="hw" type="system" is_async="true" rw_rate="250">
      <hardware><plugin>mock_components/GenericSystem</plugin><param name="a">1</param>
      <properties><async thread_priority="40" affinity="0 1" scheduling_policy="detached" print_warnings="false"/>
      </properties></hardware>
      <joint name="j"><command_interface name="position"><param name="min">-1</param><param name="max">2</param>
      </command_interface><state_interface name="position"/></joint></ros2_control></robot>"""
    (info,) = parse_control_resources(xml)
    assert info.is_async and info.rw_rate == 250 and info.hardware_parameters == {"a": "1"}
    assert info.async_params.scheduling_policy == "detached" and info.async_params.affinity == [0, 1]
    assert (info.limits["j"].min_position, info.limits["j"].max_position) == (-1.0, 2.0)


@pytest.mark.parametrize("xml, words", [
    ("<robot><ros2_control name='x' type='system'>", "not valid XML"),
    ("<robot/>", "no <ros2_control>"),
    ("<robot><ros2_control name='x' type='robot'><hardware><plugin>p</plugin></hardware></ros2_control></robot>",
     "type must be"),
    ("<robot><ros2_control name='x' type='system'><hardware/></ros2_control></robot>", "missing <hardware><plugin>"),
    ("<robot><ros2_control name='x' type='system'><hardware><plugin>p</plugin></hardware><joint name='j'>"
     "<state_interface name='position'><param name='initial_value'>abc</param></state_interface></joint>"
     "</ros2_control></robot>", "initial_value"),
])
def test_malformed_description_gives_one_clear_error(xml, words):
    with pytest.raises(DescriptionError, match=words):
        parse_control_resources(xml)


def test_unknown_plugin_is_refused_and_the_manager_stays_empty():
    cm = ControllerManager(100)
    with pytest.raises(ResourceError, match="unknown hardware plugin 'acme/Robot'.*mock_components/GenericSystem"):
        cm.load_robot_description(MOCK_UR.replace("mock_components/GenericSystem", "acme/Robot"))
    assert cm.rm.components == {}
    cm.load_robot_description(MOCK_UR)  # a good one still loads afterwards
    assert cm.rm.components["mock_ur"].state == State.ACTIVE


def test_mock_system_starts_at_initial_values_and_mirrors_commands_with_offset():
    cm = make_manager(urdf=MOCK_UR.replace('<param name="calculate_dynamics">true</param>',
                                           '<param name="position_state_following_offset">0.5</param>'))
    run(cm, 2)
    assert [cm.rm.state_interfaces[f"{j}/position"].value for j in JOINTS] == HOME
    cm.rm.command_interfaces["elbow_joint/position"].value = 1.0
    run(cm, 1)
    assert cm.rm.state_interfaces["elbow_joint/position"].value == 1.5


def test_hardware_component_lifecycle_controls_availability():
    cm = make_manager()
    assert cm.set_hardware_component_state("mock_ur", State.INACTIVE) == State.INACTIVE
    assert cm.rm.state_available("elbow_joint/position")
    assert cm.set_hardware_component_state("mock_ur", State.UNCONFIGURED) == State.UNCONFIGURED
    assert not cm.rm.state_available("elbow_joint/position")
    with pytest.raises(ResourceError, match="does not exist"):
        cm.set_hardware_component_state("nope", State.ACTIVE)


def test_initial_state_keeps_a_component_unconfigured_until_asked():
    cm = ControllerManager(100)
    cm.load_robot_description(MOCK_UR, initial_states={"mock_ur": State.UNCONFIGURED})
    assert cm.rm.components["mock_ur"].state == State.UNCONFIGURED
    assert cm.set_hardware_component_state("mock_ur", State.ACTIVE) == State.ACTIVE


def test_finalizing_hardware_logs_the_controllers_it_deactivated_and_that_restart_is_the_way_back(caplog):
    cm = make_manager()
    cm.logger = logging.getLogger("cm_finalize")
    spawn(cm, "jsb", "joint_state_broadcaster/JointStateBroadcaster")
    with caplog.at_level(logging.INFO, logger="cm_finalize"):
        assert cm.set_hardware_component_state("mock_ur", State.FINALIZED) == State.FINALIZED
        assert cm.set_hardware_component_state("mock_ur", State.ACTIVE) == State.FINALIZED
    finalized, refused = [r.getMessage() for r in caplog.records if r.name == "cm_finalize"][-2:]
    assert "hardware 'mock_ur' finalized: deactivated controller(s) ['jsb']" in finalized
    assert "cannot become active" in refused and "restart the controller manager" in refused
    assert cm.controllers["jsb"].state == State.INACTIVE


def test_deactivating_hardware_says_how_to_resume(caplog):
    cm = make_manager()
    cm.logger = logging.getLogger("cm_inactive")
    spawn(cm, "fwd", "position_controllers/JointGroupPositionController", {"joints": JOINTS})
    with caplog.at_level(logging.INFO, logger="cm_inactive"):
        cm.set_hardware_component_state("mock_ur", State.INACTIVE)
    (line,) = [r.getMessage() for r in caplog.records if r.name == "cm_inactive" and "now inactive" in r.getMessage()]
    assert "deactivated controller(s) ['fwd']" in line and "switch_controllers --activate fwd" in line
