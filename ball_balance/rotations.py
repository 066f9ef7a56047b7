"""Rotation matrices from rotation vectors and back (Rodrigues). No ROS import.

One home for this math: the URDF kinematics of ball_balance.robot and the plate kinematics
of ball_balance.control both use it.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np


def skew(w: Sequence[float]) -> np.ndarray:
    """[w]x: the matrix with [w]x v = w x v."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def rotvec_to_matrix(w: Sequence[float]) -> np.ndarray:
    """exp([w]x): rotation by |w| [rad] about w / |w| (Rodrigues)."""
    w = np.asarray(w, dtype=float)
    theta = float(np.linalg.norm(w))
    if theta < 1e-12:
        return np.eye(3) + skew(w)
    K = skew(w / theta)
    return np.eye(3) + math.sin(theta) * K + (1.0 - math.cos(theta)) * (K @ K)


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
