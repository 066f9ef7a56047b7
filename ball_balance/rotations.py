"""Rotation matrices from rotation vectors and back (Rodrigues), and to quaternions. No ROS import.

One home for this math: the URDF kinematics of ball_balance.robot and the plate kinematics
of ball_balance.control both use it.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np


def skew(w: Sequence[float]) -> np.ndarray:
    """[w]x: the matrix with [w]x v = w x v."""
    w0, w1, w2 = (float(c) for c in w)   # plain floats: building from numpy scalars is slower
    return np.array([[0.0, -w2, w1], [w2, 0.0, -w0], [-w1, w0, 0.0]])


def rotvec_to_matrix(w: Sequence[float]) -> np.ndarray:
    """exp([w]x): rotation by |w| [rad] about w / |w| (Rodrigues)."""
    w = np.asarray(w, dtype=float)
    theta = float(np.linalg.norm(w))
    if theta < 1e-12:
        return np.eye(3) + skew(w)
    K = skew(w / theta)
    return np.eye(3) + math.sin(theta) * K + (1.0 - math.cos(theta)) * (K @ K)


_EYE = np.eye(3)   # read only (axis_rotation's sums make new arrays)


def axis_rotation(axis_skew: np.ndarray, axis_skew_sq: np.ndarray, angle_rad: float) -> np.ndarray:
    """Rotation by angle_rad about a unit axis given as K = [axis]x and K @ K (Rodrigues,
    I + sin(a) K + (1 - cos(a)) K^2): a joint computes both once, and this is then a fifth
    of rotvec_to_matrix's cost. For an axis along a coordinate axis (as every UR joint's) the
    result is rotvec_to_matrix(axis * angle_rad) to the bit."""
    return _EYE + math.sin(angle_rad) * axis_skew + (1.0 - math.cos(angle_rad)) * axis_skew_sq


def matrix_to_rotvec(R: np.ndarray) -> np.ndarray:
    """log(R) as a rotation vector (inverse of rotvec_to_matrix for angles below pi)."""
    cos_t = min(1.0, max(-1.0, (np.trace(R) - 1.0) / 2.0))
    theta = math.acos(cos_t)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if theta < 1e-9:
        return 0.5 * v
    return theta / (2.0 * math.sin(theta)) * v


def axis_angle(axis: Sequence[float], angle_rad: float) -> np.ndarray:
    """Rotation by `angle_rad` about `axis` (normalised here)."""
    axis = np.asarray(axis, dtype=float)
    return rotvec_to_matrix(axis / np.linalg.norm(axis) * angle_rad)


def matrix_to_quaternion(R: np.ndarray) -> tuple:
    """Rotation matrix -> unit quaternion (x, y, z, w) with w >= 0, as geometry_msgs orders it.
    From the largest of the four squared components (no cancellation near any angle); a
    few microseconds, against about 100 us for scipy's Rotation.from_matrix().as_quat()."""
    m00, m01, m02 = float(R[0, 0]), float(R[0, 1]), float(R[0, 2])
    m10, m11, m12 = float(R[1, 0]), float(R[1, 1]), float(R[1, 2])
    m20, m21, m22 = float(R[2, 0]), float(R[2, 1]), float(R[2, 2])
    trace = m00 + m11 + m22
    if trace >= max(m00, m11, m22):
        s = 2.0 * math.sqrt(max(1.0 + trace, 0.0))
        q = ((m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s, 0.25 * s)
    elif m00 >= m11 and m00 >= m22:
        s = 2.0 * math.sqrt(max(1.0 + m00 - m11 - m22, 0.0))
        q = (0.25 * s, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s)
    elif m11 >= m22:
        s = 2.0 * math.sqrt(max(1.0 + m11 - m00 - m22, 0.0))
        q = ((m01 + m10) / s, 0.25 * s, (m12 + m21) / s, (m02 - m20) / s)
    else:
        s = 2.0 * math.sqrt(max(1.0 + m22 - m00 - m11, 0.0))
        q = ((m02 + m20) / s, (m12 + m21) / s, 0.25 * s, (m10 - m01) / s)
    norm = math.sqrt(sum(c * c for c in q))
    sign = -1.0 if q[3] < 0.0 else 1.0
    return tuple(sign * c / norm for c in q)
