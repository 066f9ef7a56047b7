"""rotations.matrix_to_quaternion against scipy, over random rotations and the awkward angles
(identity, half turns about each axis, near-half turns)."""
import math

import numpy as np
from scipy.spatial.transform import Rotation

from ball_balance.rotations import axis_angle, matrix_to_quaternion


def _same_rotation(q, expected):
    q, expected = np.array(q), np.array(expected)
    assert abs(np.linalg.norm(q) - 1.0) < 1e-12
    assert q[3] >= 0.0
    assert np.allclose(q, expected, atol=1e-9) or np.allclose(q, -expected, atol=1e-9)


def test_matches_scipy_on_random_rotations():
    rng = np.random.default_rng(3)
    for R in Rotation.random(500, random_state=rng).as_matrix():
        _same_rotation(matrix_to_quaternion(R), Rotation.from_matrix(R).as_quat())


def test_identity_half_turns_and_near_half_turns():
    matrices = [np.eye(3)]
    for axis in ([1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, -2, 3]):
        for angle in (math.pi, math.pi - 1e-7, -math.pi / 2, 1e-9):
            matrices.append(axis_angle(axis, angle))
    for R in matrices:
        _same_rotation(matrix_to_quaternion(R), Rotation.from_matrix(R).as_quat())
