"""Plate kinematics: forward kinematics from the robot description, the rotational Jacobian
J_r of the wrist joints, the (u_x, u_y) -> world-rotation wiring and least-squares IK
(docs/design.md section 6, steps 5-6). No ROS import.

Chain: the URDF joints from `base_link` to `plate_center`, each joint transform being
T_origin(xyz, rpy) * Rot(axis, q) as in URDF (rpy = fixed-axis roll, pitch, yaw:
R = Rz(yaw) Ry(pitch) Rx(roll)). The joints come from ball_balance.robot.UrdfKinematics, the
URDF reader the robot_state_publisher uses too, so FK(joint_states) equals TF
base_link -> plate_center.

Wiring (docs/design.md section 5): u_x is the tilt about the plate y axis and u_y the tilt about
the plate x axis, signed so that positive u drives the ball toward negative x / y under
x'' = -k g u. A right-handed rotation by +a about plate +y lowers the +x edge and rolls the
ball toward +x, so the plate-frame rotation vector for (u_x, u_y) is

    omega_P = (u_y, -u_x, 0)        and   R_WP_des = R_WP_home @ exp([omega_P]x)

i.e. tilts are measured from the home orientation (the level plate).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence, Tuple

import numpy as np

from ball_balance.rotations import axis_angle, axis_rotation, matrix_to_rotvec, rotvec_to_matrix, skew  # noqa: F401 (re-exported)


class KinematicsError(ValueError):
    """The robot description lacks the chain or joints we need."""


@dataclass(frozen=True)
class ChainJoint:
    name: str
    kind: str               # revolute | continuous | fixed
    origin_R: np.ndarray    # 3x3, parent link -> joint frame at q = 0
    origin_p: np.ndarray    # (3,)
    axis: np.ndarray        # (3,), in the joint frame
    lower: float = -math.inf
    upper: float = math.inf


class Chain:
    """Serial chain base -> tip; `fk(q)` takes the movable joints in `joint_names` order."""

    def __init__(self, joints: Sequence[ChainJoint], joint_names: Sequence[str]):
        self.joints = list(joints)
        movable = [j.name for j in self.joints if j.kind != "fixed"]
        missing = [n for n in joint_names if n not in movable]
        if missing:
            raise KinematicsError(f"joints {missing} are not on the chain (movable: {movable})")
        extra = [n for n in movable if n not in joint_names]
        if extra:
            raise KinematicsError(f"chain has movable joints not in joint_names: {extra}")
        self.joint_names = list(joint_names)
        self._index = {j.name: joint_names.index(j.name) for j in self.joints if j.kind != "fixed"}
        self._axis = {j.name: j.axis for j in self.joints}
        # each joint's unit axis as [axis]x and its square, once: frames() runs several times a
        # control step (axis_rotation)
        self._axis_skews = {}
        for j in self.joints:
            if j.kind != "fixed":
                K = skew(np.asarray(j.axis, dtype=float) / np.linalg.norm(j.axis))
                self._axis_skews[j.name] = (K, K @ K)
        by_name = {j.name: j for j in self.joints}
        self.lower = np.array([by_name[n].lower for n in joint_names])
        self.upper = np.array([by_name[n].upper for n in joint_names])

    @classmethod
    def from_urdf(cls, urdf_xml: str, joint_names: Sequence[str], base: str = "base_link",
                  tip: str = "plate_center") -> Chain:
        """The chain base -> tip of a robot description, parsed by ball_balance.robot (the one
        URDF reader, shared with the robot_state_publisher and the simulation)."""
        from ball_balance.robot import RobotDescriptionError, UrdfKinematics

        try:
            urdf = UrdfKinematics(urdf_xml)
            names = urdf.chain(base, tip)
        except RobotDescriptionError as error:
            raise KinematicsError(str(error)) from None
        joints = []
        for name in names:
            kind, _, _, origin, axis = urdf.joint(name)
            if kind not in ("revolute", "continuous", "fixed"):
                raise KinematicsError(f"joint '{name}' has unsupported type '{kind}'")
            joints.append(ChainJoint(name, kind, origin[:3, :3], origin[:3, 3].copy(),
                                     axis / np.linalg.norm(axis), *urdf.position_limits(name)))
        return cls(joints, joint_names)

    def frames(self, q: Sequence[float]):
        """World (base) pose of each movable joint frame and of the tip.

        Returns (joint_R: {name: 3x3}, joint_p: {name: (3,)}, R_tip, p_tip)."""
        R, p = np.eye(3), np.zeros(3)
        joint_R, joint_p = {}, {}
        for j in self.joints:
            p = p + R @ j.origin_p
            R = R @ j.origin_R
            if j.kind != "fixed":
                joint_R[j.name], joint_p[j.name] = R, p
                R = R @ axis_rotation(*self._axis_skews[j.name], q[self._index[j.name]])
        return joint_R, joint_p, R, p

    def fk(self, q: Sequence[float]) -> Tuple[np.ndarray, np.ndarray]:
        """(R_WP, p_WP): the tip orientation and position in the base frame."""
        _, _, R, p = self.frames(q)
        return R, p

    def rotational_jacobian(self, q: Sequence[float], names: Sequence[str]) -> np.ndarray:
        """J_r (3 x len(names)): world angular velocity of the tip per unit rate of each joint."""
        joint_R, _, _, _ = self.frames(q)
        return np.stack([joint_R[n] @ self._axis[n] for n in names], axis=1)

    def geometric_jacobian(self, q: Sequence[float], names: Sequence[str]) -> np.ndarray:
        """J (6 x len(names)) = [J_r; J_p]: tip angular and linear velocity (world) per joint rate,
        J_p column = axis_i x (p_tip - p_joint_i)."""
        return self.pose_and_jacobian(q, names)[2]

    def pose_and_jacobian(self, q: Sequence[float], names: Sequence[str]) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(R_WP, p_WP, J): fk(q) and geometric_jacobian(q, names) from one pass down the chain
        (the IK needs both at every iteration; the pass is most of their cost)."""
        joint_R, joint_p, R_tip, p_tip = self.frames(q)
        axes = np.array([joint_R[n] @ self._axis[n] for n in names])                 # (n, 3)
        levers = p_tip - np.array([joint_p[n] for n in names])                        # (n, 3)
        J = np.empty((6, len(names)))   # row-major, as the IK's products expect
        J[:3] = axes.T
        # axes x levers, written out (np.cross costs more than the products for three rows)
        J[3] = axes[:, 1] * levers[:, 2] - axes[:, 2] * levers[:, 1]
        J[4] = axes[:, 2] * levers[:, 0] - axes[:, 0] * levers[:, 2]
        J[5] = axes[:, 0] * levers[:, 1] - axes[:, 1] * levers[:, 0]
        return R_tip, p_tip, J


@dataclass(frozen=True)
class ShaperConfig:
    max_joint_step_rad: float = 0.02     # per tick, per joint
    max_tilt_rad: float = 0.20           # total plate tilt from home
    joint_margin_rad: float = 0.05       # stay this far inside the URDF limits


class PlateKinematics:
    """Tilt pair -> 6 joint positions: wiring, IK on the wrist joints, shaping and limits.

    `home_q` (6,) defines the level plate (zero tilt). Two IK modes:

    - "wrist" (docs/design.md section 6): only the `wrist` joints move, least squares on J_r; the
      others stay at home. The plate then pivots about the wrist axes, which lie 0.11 m
      below the plate centre on the UR5e: tilting accelerates the plate sideways, and the
      ball feels x'' = -k g u + k h u'' (h = 0.11 m), a right-half-plane zero at
      sqrt(g / h) ~ 9 rad/s that caps the usable loop bandwidth.
    - "pivot": all 6 joints, least squares on the geometric Jacobian [J_r; J_p], holding the
      plate centre where it is at home: the plate tilts about its own centre, the zero is
      gone. The default in config/*.yaml (measured better in the benchmark).
    """

    def __init__(self, chain: Chain, home_q: Sequence[float],
                 wrist: Sequence[str] = ("wrist_1_joint", "wrist_2_joint", "wrist_3_joint"),
                 shaper: ShaperConfig = ShaperConfig(), damping: float = 1e-4, mode: str = "wrist"):
        if mode not in ("wrist", "pivot"):
            raise KinematicsError(f"ik mode '{mode}' must be 'wrist' or 'pivot'")
        self.chain, self.shaper, self.damping, self.mode = chain, shaper, damping, mode
        self.home_q = np.asarray(home_q, dtype=float)
        self.wrist = list(wrist)
        self.wrist_idx = [chain.joint_names.index(n) for n in wrist]
        self.R_WP_home, self.p_WP_home = chain.fk(self.home_q)
        m = shaper.joint_margin_rad
        self.q_min = np.where(np.isfinite(chain.lower), chain.lower + m, -math.inf)
        self.q_max = np.where(np.isfinite(chain.upper), chain.upper - m, math.inf)

    # --- wiring ---------------------------------------------------------------------
    @staticmethod
    def plate_rotvec(u_x: float, u_y: float) -> np.ndarray:
        """omega_P for the tilt pair (see the module docstring)."""
        return np.array([u_y, -u_x, 0.0])

    def desired_rotation(self, u_x: float, u_y: float) -> np.ndarray:
        """R_WP_des for the tilt pair, limited to max_tilt_rad in total."""
        w = self.plate_rotvec(u_x, u_y)
        norm = float(np.linalg.norm(w))
        if norm > self.shaper.max_tilt_rad:
            w *= self.shaper.max_tilt_rad / norm
        return self.R_WP_home @ rotvec_to_matrix(w)

    def tilt_of(self, q: Sequence[float]) -> Tuple[float, float]:
        """(u_x, u_y) of the plate at joint positions q, measured from home."""
        w = matrix_to_rotvec(self.R_WP_home.T @ self.chain.fk(q)[0])
        return float(-w[1]), float(w[0])

    # --- IK -------------------------------------------------------------------------
    def ik(self, q_start: Sequence[float], R_des: np.ndarray, iterations: int = 3) -> np.ndarray:
        """Damped least squares on the wrist joints: dq = J_r^T (J_r J_r^T + l I)^-1 e,
        e = log(R_des R_WP^T) (world frame). Non-wrist joints are set to home.
        In "pivot" mode: all joints, J = [J_r; J_p], e = [log(R_des R_WP^T); p_home - p_WP]."""
        q = np.asarray(q_start, dtype=float).copy()
        if self.mode == "pivot":
            return self._ik_pivot(q, R_des, iterations)
        others = [i for i in range(len(q)) if i not in self.wrist_idx]
        q[others] = self.home_q[others]
        for _ in range(iterations):
            R, _ = self.chain.fk(q)
            e = matrix_to_rotvec(R_des @ R.T)
            if np.linalg.norm(e) < 1e-10:
                break
            J_r = self.chain.rotational_jacobian(q, self.wrist)
            dq = J_r.T @ np.linalg.solve(J_r @ J_r.T + self.damping * np.eye(3), e)
            q[self.wrist_idx] += dq
        return q

    def _ik_pivot(self, q: np.ndarray, R_des: np.ndarray, iterations: int) -> np.ndarray:
        names = self.chain.joint_names
        for _ in range(iterations):
            R, p, J = self.chain.pose_and_jacobian(q, names)
            e = np.concatenate([matrix_to_rotvec(R_des @ R.T), self.p_WP_home - p])
            if np.linalg.norm(e) < 1e-10:
                break
            q = q + J.T @ np.linalg.solve(J @ J.T + self.damping * np.eye(6), e)
        return q

    # --- shaping --------------------------------------------------------------------
    def shape(self, q_target: np.ndarray, q_prev: np.ndarray) -> np.ndarray:
        """Step toward q_target within the per-joint step limit, then the joint limits.

        The step limit scales the whole joint step (no joint moves more than
        max_joint_step_rad) instead of clipping joints one by one, so the motion keeps the
        IK's direction: the tilt direction, and in "pivot" mode the plate centre, hold."""
        s = self.shaper
        step = q_target - q_prev
        largest = float(np.max(np.abs(step))) if step.size else 0.0
        if largest > s.max_joint_step_rad:
            step *= s.max_joint_step_rad / largest
        return np.clip(q_prev + step, self.q_min, self.q_max)

    def command(self, u_x: float, u_y: float, q_prev: np.ndarray) -> np.ndarray:
        """The shaped 6-joint command for the tilt pair, starting from the last command."""
        return self.shape(self.ik(q_prev, self.desired_rotation(u_x, u_y)), q_prev)
