"""Rigid transforms with unit quaternions, in plain Python (no numpy, no rclpy).

Convention (tf2's): `T_A_B` is the pose of frame B expressed in frame A; it maps a point
given in B into A: p_A = T_A_B * p_B = R_AB p_B + t_AB. Composition: T_A_C = T_A_B * T_B_C.
Quaternions are (x, y, z, w), like geometry_msgs/Quaternion. Translations in metres.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Tuple

Vector3 = Tuple[float, float, float]
Quaternion = Tuple[float, float, float, float]  # (x, y, z, w)

IDENTITY_Q: Quaternion = (0.0, 0.0, 0.0, 1.0)


def quat_normalize(q: Quaternion) -> Quaternion:
    """q / |q|; raises ValueError for a zero or non-finite quaternion."""
    norm = math.sqrt(sum(c * c for c in q))
    if not math.isfinite(norm) or norm < 1e-12:
        raise ValueError(f"quaternion {tuple(q)} cannot be normalized (norm {norm})")
    return (q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm)


def quat_multiply(a: Quaternion, b: Quaternion) -> Quaternion:
    """Hamilton product a * b (rotate by b first, then by a)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


def quat_conjugate(q: Quaternion) -> Quaternion:
    """The inverse rotation of a unit quaternion."""
    return (-q[0], -q[1], -q[2], q[3])


def quat_rotate(q: Quaternion, v: Vector3) -> Vector3:
    """R(q) v, via v' = v + 2 w (u x v) + 2 u x (u x v) with u the vector part."""
    ux, uy, uz, w = q
    vx, vy, vz = v
    # c = u x v
    cx, cy, cz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    # d = u x c
    dx, dy, dz = uy * cz - uz * cy, uz * cx - ux * cz, ux * cy - uy * cx
    return (vx + 2.0 * (w * cx + dx), vy + 2.0 * (w * cy + dy), vz + 2.0 * (w * cz + dz))


def quat_from_euler(roll: float, pitch: float, yaw: float) -> Quaternion:
    """Fixed-axis roll (x), pitch (y), yaw (z) in radians: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)


def quat_to_euler(q: Quaternion) -> Tuple[float, float, float]:
    """(roll, pitch, yaw) in radians, the inverse of quat_from_euler."""
    x, y, z, w = q
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def slerp(a: Quaternion, b: Quaternion, s: float) -> Quaternion:
    """Spherical interpolation from a (s=0) to b (s=1) along the shorter arc."""
    dot = sum(ca * cb for ca, cb in zip(a, b, strict=True))
    if dot < 0.0:  # q and -q are the same rotation: take the short way
        b, dot = tuple(-c for c in b), -dot
    if dot > 0.9995:  # nearly parallel: normalized lerp is exact enough and stable
        return quat_normalize(tuple(ca + s * (cb - ca) for ca, cb in zip(a, b, strict=True)))
    theta = math.acos(dot)
    sin_theta = math.sin(theta)
    wa, wb = math.sin((1 - s) * theta) / sin_theta, math.sin(s * theta) / sin_theta
    return tuple(wa * ca + wb * cb for ca, cb in zip(a, b, strict=True))


@dataclass(frozen=True)
class Transform:
    """T_A_B: translation t_AB (metres, in A) and rotation q_AB (x, y, z, w)."""

    translation: Vector3 = (0.0, 0.0, 0.0)
    rotation: Quaternion = IDENTITY_Q

    @staticmethod
    def from_values(translation, rotation) -> Transform:
        """Validated construction: finite numbers, rotation normalized."""
        t = tuple(float(c) for c in translation)
        if len(t) != 3 or not all(math.isfinite(c) for c in t):
            raise ValueError(f"translation {translation} must be 3 finite numbers")
        r = tuple(float(c) for c in rotation)
        if len(r) != 4:
            raise ValueError(f"rotation {rotation} must be a quaternion (x, y, z, w)")
        return Transform(t, quat_normalize(r))

    def __mul__(self, other: Transform) -> Transform:
        """T_A_C = T_A_B * T_B_C."""
        rt = quat_rotate(self.rotation, other.translation)
        t = (self.translation[0] + rt[0], self.translation[1] + rt[1], self.translation[2] + rt[2])
        return Transform(t, quat_multiply(self.rotation, other.rotation))

    def inverse(self) -> Transform:
        """T_B_A = T_A_B^-1: R^T, -R^T t."""
        q_inv = quat_conjugate(self.rotation)
        t = quat_rotate(q_inv, self.translation)
        return Transform((-t[0], -t[1], -t[2]), q_inv)

    def apply(self, point: Vector3) -> Vector3:
        """p_A = T_A_B p_B."""
        r = quat_rotate(self.rotation, point)
        return (r[0] + self.translation[0], r[1] + self.translation[1], r[2] + self.translation[2])

    def interpolate(self, other: Transform, s: float) -> Transform:
        """Linear in translation, slerp in rotation; s=0 gives self, s=1 gives other."""
        t = tuple(a + s * (b - a) for a, b in zip(self.translation, other.translation, strict=True))
        return Transform(t, slerp(self.rotation, other.rotation, s))

    def is_close(self, other: Transform, tol: float = 1e-9) -> bool:
        """Same transform within tol (q and -q count as equal)."""
        dt = max(abs(a - b) for a, b in zip(self.translation, other.translation, strict=True))
        dot = abs(sum(a * b for a, b in zip(self.rotation, other.rotation, strict=True)))
        return dt <= tol and 1.0 - dot <= tol
