"""The robot: joint names, home pose, and the one robot description (config/ur5e_ball_balance.urdf).

No ROS import. Used by the simulation (which compiles the same URDF into MuJoCo), the
robot_state_publisher (URDF kinematics below), the controllers (names, home pose) and the
scripts (`python -m ball_balance.robot --hardware mock` prints the description with the
mock hardware selected).

- `JOINT_NAMES`: UR joint order, the order of every joint vector in this project.
- `HOME_POSITIONS_RAD`: plate level (normal = world +z) under the overhead camera; at home
  the wrist axes are world y (wrist_1), world x (wrist_2) and world z (wrist_3).
- `robot_description(hardware=...)`: the URDF text with the `<ros2_control>` hardware
  plugin selected: "mujoco" (default, `ball_balance/MujocoSystem`), "mock"
  (`mock_components/GenericSystem`) or "ur" (the real UR driver's plugin; placeholder).
- `UrdfKinematics`: per-joint transforms from the URDF (fixed joints, moving joints at a
  position), and forward kinematics between any two links.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from ball_balance.plate_geometry import PLATE_FRAME
from ball_balance.rotations import axis_angle

PACKAGE = "ball_balance"
DESCRIPTION_FILE = "ur5e_ball_balance.urdf"
BASE_FRAME = "base_link"
TOOL_FRAME = "tool0"

JOINT_NAMES: Tuple[str, ...] = (
    "shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
    "wrist_1_joint", "wrist_2_joint", "wrist_3_joint",
)
HOME_POSITIONS_RAD: Tuple[float, ...] = (0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, math.pi / 2, 0.0)

# hardware name -> <ros2_control><hardware><plugin> value, and that plugin's default params
HARDWARE_PLUGINS: Dict[str, str] = {
    "mujoco": "ball_balance/MujocoSystem",
    "mock": "mock_components/GenericSystem",
    "ur": "ur_robot_driver/URPositionHardwareInterface",
}
HARDWARE_DEFAULT_PARAMS: Dict[str, Dict[str, str]] = {
    "mujoco": {},
    "mock": {"calculate_dynamics": "false"},
    "ur": {"robot_ip": "192.168.56.101", "script_filename": "", "output_recipe_filename": "",
           "input_recipe_filename": ""},
}


def joint_dict(values: Sequence[float]) -> Dict[str, float]:
    """{joint name: value} for a 6-vector in JOINT_NAMES order."""
    return dict(zip(JOINT_NAMES, (float(v) for v in values), strict=True))


class RobotDescriptionError(ValueError):
    """The robot description is missing, malformed, or lacks something we need."""


def robot_description_path() -> Path:
    """config/ur5e_ball_balance.urdf: from the installed share dir, else the source tree."""
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            candidate = Path(prefix) / "share" / PACKAGE / "config" / DESCRIPTION_FILE
            if candidate.is_file():
                return candidate
    candidate = Path(__file__).resolve().parents[1] / "config" / DESCRIPTION_FILE
    if candidate.is_file():
        return candidate
    raise RobotDescriptionError(f"{DESCRIPTION_FILE} not found in the ament index or {candidate.parent}")


def robot_description(hardware: str = "mujoco", params: Optional[Mapping[str, object]] = None,
                      urdf_text: Optional[str] = None) -> str:
    """The URDF text with the `<ros2_control>` hardware plugin set to `hardware`.

    `params` replace/add `<param>` entries of the `<hardware>` element (values as str).
    Raises RobotDescriptionError for an unknown hardware name or a URDF without
    `<ros2_control><hardware>`.
    """
    if hardware not in HARDWARE_PLUGINS:
        raise RobotDescriptionError(
            f"unknown hardware '{hardware}': expected one of {sorted(HARDWARE_PLUGINS)}")
    text = urdf_text if urdf_text is not None else robot_description_path().read_text()
    root = _parse(text)
    hw = root.find("ros2_control/hardware")
    if hw is None:
        raise RobotDescriptionError("robot description has no <ros2_control><hardware> element")
    plugin = hw.find("plugin")
    if plugin is None:
        plugin = ET.SubElement(hw, "plugin")
    plugin.text = HARDWARE_PLUGINS[hardware]
    if hardware != "mujoco":  # MuJoCo params make no sense for other hardware
        for element in hw.findall("param"):
            hw.remove(element)
    wanted = dict(HARDWARE_DEFAULT_PARAMS[hardware])
    wanted.update({k: _param_text(v) for k, v in (params or {}).items()})
    for name, value in wanted.items():
        element = next((p for p in hw.findall("param") if p.get("name") == name), None)
        if element is None:
            element = ET.SubElement(hw, "param", name=name)
        element.text = value
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode")


def hardware_plugin(urdf_text: str) -> str:
    """The `<ros2_control><hardware><plugin>` of a description (RobotDescriptionError if absent)."""
    plugin = _parse(urdf_text).find("ros2_control/hardware/plugin")
    if plugin is None or not (plugin.text or "").strip():
        raise RobotDescriptionError("robot description has no <ros2_control><hardware><plugin>")
    return plugin.text.strip()


def hardware_params(urdf_text: str) -> Dict[str, str]:
    """The `<param name=...>` entries of `<ros2_control><hardware>` as strings."""
    hw = _parse(urdf_text).find("ros2_control/hardware")
    return {} if hw is None else {p.get("name"): (p.text or "").strip() for p in hw.findall("param")}


def check_robot_description(urdf_text: str, required_links: Sequence[str] = (BASE_FRAME, TOOL_FRAME, PLATE_FRAME),
                            ) -> None:
    """Raise RobotDescriptionError unless the URDF has our links and the six UR joints."""
    root = _parse(urdf_text)
    links = {link.get("name") for link in root.findall("link")}
    missing = [name for name in required_links if name not in links]
    if missing:
        raise RobotDescriptionError(f"robot description lacks link(s) {missing} (the plate is link "
                                    f"'{PLATE_FRAME}' fixed on '{TOOL_FRAME}')")
    joints = {joint.get("name") for joint in root.findall("joint")}
    missing = [name for name in JOINT_NAMES if name not in joints]
    if missing:
        raise RobotDescriptionError(f"robot description lacks joint(s) {missing}")


@dataclass(frozen=True)
class JointLimit:
    """A URDF <limit>: position range (rad), velocity (rad/s), effort (N m)."""

    lower: float
    upper: float
    velocity: float
    effort: float


def joint_limits(urdf_text: str) -> Dict[str, JointLimit]:
    """JointLimit of each of JOINT_NAMES from the URDF (RobotDescriptionError when one lacks <limit>)."""
    root = _parse(urdf_text)
    limits = {}
    for joint in root.findall("joint"):
        name = joint.get("name")
        if name not in JOINT_NAMES:
            continue
        limit = joint.find("limit")
        if limit is None:
            raise RobotDescriptionError(f"joint '{name}' has no <limit>")
        try:
            limits[name] = JointLimit(*(float(limit.get(key, "nan"))
                                        for key in ("lower", "upper", "velocity", "effort")))
        except ValueError:
            raise RobotDescriptionError(f"joint '{name}' has a malformed <limit>") from None
    missing = [name for name in JOINT_NAMES if name not in limits]
    if missing:
        raise RobotDescriptionError(f"robot description lacks joint(s) {missing}")
    return limits


def _parse(text: str) -> ET.Element:
    try:
        root = ET.fromstring(text.encode() if isinstance(text, str) else text)
    except ET.ParseError as error:
        raise RobotDescriptionError(f"robot description is not valid XML: {error}") from None
    if root.tag != "robot":
        raise RobotDescriptionError(f"robot description root is <{root.tag}>, expected <robot>")
    return root


def _param_text(value: object) -> str:
    return str(value).lower() if isinstance(value, bool) else str(value)


# ----------------------------------------------------------------------------------------
# URDF kinematics (yourdfpy parses; the math is a product of joint transforms)

class UrdfKinematics:
    """Joint transforms of a URDF: T_parent_child = origin @ motion(q).

    `fixed_transforms()` lists (parent, child, T) for fixed joints; `joint_transform(name, q)`
    gives one moving joint's (parent, child, T); `transform(target, source, positions)` is
    T_source_target (a point in `target` coordinates mapped into `source`), joints missing from
    `positions` at 0.
    """

    MOVING_TYPES = ("revolute", "continuous", "prismatic")

    def __init__(self, urdf_text: str):
        import yourdfpy

        _parse(urdf_text)
        try:
            urdf = yourdfpy.URDF.load(_TextFile(urdf_text), build_scene_graph=False, load_meshes=False,
                                      build_collision_scene_graph=False, load_collision_meshes=False)
        except Exception as error:  # yourdfpy raises several types for a malformed URDF
            raise RobotDescriptionError(f"cannot parse robot description: {error}") from None
        self.robot_name = urdf.robot.name
        self._joints = {}
        self._parent_joint = {}
        self._position_limits = {}
        for joint in urdf.robot.joints:
            limit = joint.limit
            if joint.type == "revolute" and limit is not None and None not in (limit.lower, limit.upper):
                self._position_limits[joint.name] = (float(limit.lower), float(limit.upper))
            origin = np.eye(4) if joint.origin is None else np.asarray(joint.origin, dtype=float)
            axis = np.array([1.0, 0.0, 0.0]) if joint.axis is None else np.asarray(joint.axis, dtype=float)
            self._joints[joint.name] = (joint.type, joint.parent, joint.child, origin, axis)
            self._parent_joint[joint.child] = joint.name
        self.links = [link.name for link in urdf.robot.links]
        roots = [name for name in self.links if name not in self._parent_joint]
        self.root = roots[0] if roots else None

    @property
    def moving_joints(self) -> List[str]:
        return [n for n, j in self._joints.items() if j[0] in self.MOVING_TYPES]

    def joint(self, name: str) -> Tuple[str, str, str, np.ndarray, np.ndarray]:
        """(type, parent, child, origin 4x4, axis) of one joint as the URDF gives it."""
        return self._joints[name]

    def position_limits(self, name: str) -> Tuple[float, float]:
        """(lower, upper) [rad] of a revolute joint; unbounded for other joints."""
        return self._position_limits.get(name, (-math.inf, math.inf))

    def chain(self, base: str, tip: str) -> List[str]:
        """Names of the joints from `base` down to `tip`, in order from the base."""
        names, link = [], tip
        while link != base:
            if link not in self._parent_joint:
                raise RobotDescriptionError(f"no chain from '{base}' to '{tip}' (link '{link}' has no parent joint)")
            names.append(self._parent_joint[link])
            link = self._joints[names[-1]][1]
        return names[::-1]

    def fixed_transforms(self) -> List[Tuple[str, str, np.ndarray]]:
        return [(parent, child, origin) for kind, parent, child, origin, _ in self._joints.values()
                if kind not in self.MOVING_TYPES]

    def joint_transform(self, name: str, position: float) -> Tuple[str, str, np.ndarray]:
        kind, parent, child, origin, axis = self._joints[name]
        motion = np.eye(4)
        if kind in ("revolute", "continuous"):
            motion[:3, :3] = axis_angle(axis, position)
        elif kind == "prismatic":
            motion[:3, 3] = axis / np.linalg.norm(axis) * position
        return parent, child, origin @ motion

    def transform(self, target: str, source: str = BASE_FRAME,
                  positions: Optional[Mapping[str, float]] = None) -> np.ndarray:
        """T_source_target (4x4): pose of frame `target` expressed in frame `source`."""
        positions = positions or {}
        return np.linalg.inv(self._to_root(source, positions)) @ self._to_root(target, positions)

    def _to_root(self, link: str, positions: Mapping[str, float]) -> np.ndarray:
        if link not in self.links:
            raise RobotDescriptionError(f"unknown link '{link}'")
        T = np.eye(4)
        while link in self._parent_joint:
            name = self._parent_joint[link]
            parent, _, T_joint = self.joint_transform(name, float(positions.get(name, 0.0)))
            T = T_joint @ T
            link = parent
        return T


class _TextFile:
    """A file-like object over URDF text for yourdfpy.URDF.load (which wants a file)."""

    def __init__(self, text: str):
        import io

        self._buffer = io.BytesIO(text.encode())

    def read(self, *args):
        return self._buffer.read(*args)


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description="Print the robot description with a hardware plugin selected.")
    parser.add_argument("--hardware", default="mujoco", help=f"one of {sorted(HARDWARE_PLUGINS)}")
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                        help="a <hardware> <param> (repeatable)")
    args = parser.parse_args(argv)
    try:
        params = {}
        for item in args.param:
            name, equals, value = item.partition("=")
            if not name or not equals:
                raise ValueError(f"--param takes NAME=VALUE, got '{item}'")
            params[name] = value
        print(robot_description(args.hardware, params))
    except (RobotDescriptionError, ValueError) as error:
        print(f"robot: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
