"""The robot description: official UR5e kinematics, the plate link, hardware selection, and
MuJoCo compiled from the same URDF agreeing with yourdfpy forward kinematics."""
import math

import mujoco
import numpy as np
import pytest
import yourdfpy

from ball_balance import robot
from ball_balance.plate_geometry import PLATE_MOUNT_OFFSET_M
from ball_balance.sim.world import SimWorld

FRAMES = ("shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link",
          "wrist_3_link", "flange", "tool0", "plate_center")


@pytest.fixture(scope="module")
def world():
    world = SimWorld()
    yield world
    world.close()


def test_mujoco_forward_kinematics_matches_yourdfpy_at_random_configurations(world):
    urdf = yourdfpy.URDF.load(str(robot.robot_description_path()), load_meshes=False)
    rng = np.random.default_rng(4)
    data = mujoco.MjData(world.model)
    for _ in range(20):
        q = rng.uniform(world.lower_rad, world.upper_rad)
        urdf.update_cfg(q)
        data.qpos[world.ids.qpos_arm] = q
        mujoco.mj_kinematics(world.model, data)
        for frame in FRAMES:
            T = urdf.get_transform(frame, "base_link")
            body = world.model.body(frame).id
            assert np.allclose(data.xpos[body], T[:3, 3], atol=1e-6), frame
            assert np.allclose(data.xmat[body].reshape(3, 3), T[:3, :3], atol=1e-6), frame


def test_urdf_kinematics_matches_yourdfpy():
    text = robot.robot_description()
    kin = robot.UrdfKinematics(text)
    urdf = yourdfpy.URDF.load(str(robot.robot_description_path()), load_meshes=False)
    q = np.array([0.3, -1.2, 1.1, -0.4, 0.9, 2.0])
    urdf.update_cfg(q)
    T = kin.transform("plate_center", "base_link", robot.joint_dict(q))
    assert np.allclose(T, urdf.get_transform("plate_center", "base_link"), atol=1e-12)


def test_urdf_has_the_official_ur5e_kinematics_and_limits():
    kin = robot.UrdfKinematics(robot.robot_description())
    zero = robot.joint_dict([0.0] * 6)
    shoulder = kin.transform("shoulder_link", "base_link", zero)
    assert shoulder[2, 3] == pytest.approx(0.1625)                      # d1
    elbow = kin.transform("forearm_link", "upper_arm_link", zero)
    assert elbow[0, 3] == pytest.approx(-0.425)                         # a2
    wrist_1 = kin.transform("wrist_1_link", "forearm_link", zero)
    assert (wrist_1[0, 3], wrist_1[2, 3]) == pytest.approx((-0.3922, 0.1333))  # a3, d4
    assert kin.transform("wrist_2_link", "wrist_1_link", zero)[1, 3] == pytest.approx(-0.0997)  # d5
    assert kin.transform("wrist_3_link", "wrist_2_link", zero)[1, 3] == pytest.approx(0.0996)   # d6
    limits = robot.joint_limits(robot.robot_description())
    assert [limits[n].effort for n in robot.JOINT_NAMES] == [150, 150, 150, 28, 28, 28]
    assert all(limits[n].velocity == pytest.approx(3.14) for n in robot.JOINT_NAMES)
    assert limits["elbow_joint"].upper == pytest.approx(math.pi)
    assert limits["shoulder_pan_joint"].upper == pytest.approx(2 * math.pi)


def test_plate_is_fixed_on_tool0_along_its_z_axis():
    kin = robot.UrdfKinematics(robot.robot_description())
    T = kin.transform("plate_center", "tool0")
    assert np.allclose(T[:3, :3], np.eye(3))
    assert np.allclose(T[:3, 3], [0.0, 0.0, PLATE_MOUNT_OFFSET_M])
    assert ("tool0", "plate_center") in [(p, c) for p, c, _ in kin.fixed_transforms()]


def test_home_pose_holds_the_plate_level():
    kin = robot.UrdfKinematics(robot.robot_description())
    T = kin.transform("plate_center", "base_link", robot.joint_dict(robot.HOME_POSITIONS_RAD))
    assert np.allclose(T[:3, 2], [0.0, 0.0, 1.0], atol=1e-9)
    assert T[2, 3] > 0.5


@pytest.mark.parametrize("hardware", sorted(robot.HARDWARE_PLUGINS))
def test_hardware_plugin_is_selectable(hardware):
    text = robot.robot_description(hardware)
    assert robot.hardware_plugin(text) == robot.HARDWARE_PLUGINS[hardware]
    robot.check_robot_description(text)


def test_default_description_file_selects_mujoco():
    assert robot.hardware_plugin(robot.robot_description_path().read_text()) == "ball_balance/MujocoSystem"


def test_unknown_hardware_is_refused_with_the_known_names():
    with pytest.raises(robot.RobotDescriptionError, match="unknown hardware 'gazebo'.*mock"):
        robot.robot_description("gazebo")


def test_hardware_params_are_written_into_the_description():
    text = robot.robot_description("mujoco", {"camera_rate_hz": 60, "sim_time": True})
    params = robot.hardware_params(text)
    assert params["camera_rate_hz"] == "60" and params["sim_time"] == "true"


def test_description_without_plate_link_is_refused():
    text = robot.robot_description().replace('<link name="plate_center">', '<link name="tray">')
    text = text.replace('<child link="plate_center"/>', '<child link="tray"/>')
    with pytest.raises(robot.RobotDescriptionError, match="plate_center"):
        robot.check_robot_description(text)
    with pytest.raises(robot.RobotDescriptionError, match="plate_center"):
        SimWorld(urdf_text=text)


def test_malformed_description_is_refused():
    with pytest.raises(robot.RobotDescriptionError, match="not valid XML"):
        robot.check_robot_description("<robot><link name='a'></robot>")


@pytest.mark.parametrize("hardware", ["mock", "mujoco"])
def test_description_loads_in_the_controller_manager(hardware):
    from controller_manager_py.manager.controller_manager import ControllerManager

    cm = ControllerManager(500)
    cm.load_robot_description(robot.robot_description(hardware, {"camera_enabled": False} if hardware == "mujoco"
                                                      else None))
    names = set(cm.rm.state_interfaces)
    assert {f"{j}/position" for j in robot.JOINT_NAMES} <= names
    assert "speed_scaling/speed_scaling_factor" in names
    cm.shutdown()


def test_urdf_plate_matches_plate_geometry():
    import xml.etree.ElementTree as ET

    from ball_balance.plate_geometry import PLATE_MASS_KG, PLATE_SIDE_M, PLATE_THICKNESS_M

    link = ET.fromstring(robot.robot_description()).find("link[@name='plate_center']")
    sizes = [tuple(float(v) for v in box.get("size").split()) for box in link.iter("box")]
    assert sizes and all(s == pytest.approx((PLATE_SIDE_M, PLATE_SIDE_M, PLATE_THICKNESS_M)) for s in sizes)
    assert float(link.find("inertial/mass").get("value")) == pytest.approx(PLATE_MASS_KG)
