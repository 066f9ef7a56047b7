"""How good is the plate pose behind a ball estimate: pose covariance and the ball error it causes.

The tracker measures the plate's pose in the camera from the ArUco marker corners and maps
the ball's pixel onto the plate through it. Corner noise makes the pose uncertain, and an
uncertain pose moves the ball's plate coordinates even when the ball's pixel is exact. With
four markers that error is a fraction of a millimetre; with one marker left (a hand over
the plate) the tilt is barely observable and it can reach centimetres.

Conventions (those of geometry_msgs/PoseWithCovariance, as published on /plate_pose):
- pose: plate_center in the camera frame, X_C = R_CP X_P + t_CP;
- covariance: 6x6, row-major, order [x y z rx ry rz], m^2 and rad^2; the translation error
  is a displacement of t_CP in camera axes, the rotation error a small rotation about the
  camera's (fixed) axes: R_CP_true = exp([dphi]x) R_CP_estimated;
- no usable pose: every diagonal element is +inf (see `UNUSABLE_COVARIANCE`).

`ball_position_std_m(covariance)` reduces the covariance to one number a controller can
gate on: the 1-sigma error of the ball's plate position (metres) caused by the pose, in its
worst direction, at the worst place on the plate the ball can reach. It assumes the camera
looks along the plate normal from `camera_height_m` above its centre (the overhead camera of
the design); a camera a few tens of degrees off that changes the figure by a few per cent.

Pure numpy, no ROS.
"""
from __future__ import annotations

import functools
import math
from typing import Optional, Sequence, Union

import numpy as np

from ball_balance.plate_geometry import BALL_RADIUS_M, PLATE_SIDE_M
from ball_balance.rotations import skew

# The overhead camera: camera x = plate x, camera y = -plate y, optical axis = -plate z.
R_CP_OVERHEAD = np.diag([1.0, -1.0, -1.0])
DEFAULT_CAMERA_HEIGHT_M = 0.65                       # the simulated camera's height above the plate
DEFAULT_REACH_M = PLATE_SIDE_M / 2.0 - BALL_RADIUS_M  # |x|, |y| of the ball centre on the plate
UNUSABLE_COVARIANCE = tuple(math.inf if i % 7 == 0 else 0.0 for i in range(36))

CovarianceLike = Union[np.ndarray, Sequence[float]]


def projection_jacobian(plate_pts: np.ndarray, K: np.ndarray, R_CP: np.ndarray, t_CP: np.ndarray) -> np.ndarray:
    """d(pixel) / d[dt, dphi] for plate points (n, 2) on z = 0: shape (2n, 6), rows u0 v0 u1 v1 ...

    Perturbation as in the module docstring: X_C = exp([dphi]x) R_CP X_P + t_CP + dt, so
    dX_C/d dt = I and dX_C/d dphi = -[R_CP X_P]x."""
    points = np.column_stack([plate_pts, np.zeros(len(plate_pts))])
    RX = points @ R_CP.T                                        # R_CP X_P, (n, 3)
    X = RX + t_CP                                               # camera coordinates
    fx, s, fy = K[0, 0], K[0, 1], K[1, 1]
    Xc, Yc, Zc = X.T
    zero = np.zeros_like(Zc)
    # d(u, v)/dX_C per point, (n, 2, 3)
    d_proj = np.stack([np.stack([fx / Zc, s / Zc, -(fx * Xc + s * Yc) / Zc ** 2], axis=-1),
                       np.stack([zero, fy / Zc, -fy * Yc / Zc ** 2], axis=-1)], axis=1)
    # -[RX]x per point, (n, 3, 3)
    a, b, c = RX.T
    minus_skew = np.stack([np.stack([zero, c, -b], axis=-1), np.stack([-c, zero, a], axis=-1),
                           np.stack([b, -a, zero], axis=-1)], axis=1)
    J = np.concatenate([d_proj, d_proj @ minus_skew], axis=2)   # (n, 2, 6)
    J = J.reshape(-1, 6)
    return J


def pose_covariance(plate_pts: np.ndarray, K: np.ndarray, R_CP: np.ndarray, t_CP: np.ndarray,
                    sigma_px: float, prior_information: Optional[np.ndarray] = None) -> np.ndarray:
    """Covariance (6x6, [x y z rx ry rz], camera frame) of a pose fitted to the image corners of
    `plate_pts` (n, 2) with independent pixel noise `sigma_px` (1 sigma per coordinate):
    inv(J^T J / sigma_px^2 + prior_information). `prior_information` (6x6, same order) is the
    pose prior of a fit that has one (the 1-2 marker pivot fit); UNUSABLE when singular."""
    J = projection_jacobian(plate_pts, K, R_CP, t_CP)
    information = J.T @ J / sigma_px ** 2
    if prior_information is not None:
        information = information + prior_information
    if np.linalg.cond(information) > 1e12:
        return np.array(UNUSABLE_COVARIANCE).reshape(6, 6)
    covariance = np.linalg.inv(information)
    return 0.5 * (covariance + covariance.T)


def ball_error_jacobian(ball_xy_m: Sequence[float], camera_height_m: float = DEFAULT_CAMERA_HEIGHT_M,
                        R_CP: np.ndarray = R_CP_OVERHEAD, ball_radius_m: float = BALL_RADIUS_M) -> np.ndarray:
    """d(ball plate xy) / d[dt, dphi] (2x6) for a ball at `ball_xy_m`, camera above the centre.

    The ball's camera-frame point X is fixed (its pixel is exact); the estimated plate frame
    sees it at p + dp with dp = -R^T dt + [p]x R^T dphi. The tracker then slides along the
    camera ray d = p - C to the plane z = r: dp_xy - dp_z d_xy / d_z."""
    p = np.array([ball_xy_m[0], ball_xy_m[1], ball_radius_m])
    A = np.hstack([-R_CP.T, skew(p) @ R_CP.T])                  # dp, (3, 6)
    slope = p[:2] / (ball_radius_m - camera_height_m)           # d_xy / d_z, C = (0, 0, h)
    return A[:2] - np.outer(slope, A[2])


def ball_position_std_m(covariance: CovarianceLike, camera_height_m: float = DEFAULT_CAMERA_HEIGHT_M,
                        reach_m: float = DEFAULT_REACH_M) -> float:
    """1-sigma error (m) of the ball's plate position caused by the plate pose's covariance.

    `covariance`: 36 numbers row-major (PoseWithCovariance.covariance) or a 6x6 array, order
    [x y z rx ry rz] in the camera frame. Returns the standard deviation in the worst
    direction (sqrt of the largest eigenvalue of the 2x2 plate-xy covariance), the worst of
    the plate centre and the four corners of the square |x|, |y| <= `reach_m` where the
    ball's centre can be. math.inf when the covariance is not usable (non-finite, negative
    variances, wrong size): there is no pose to trust."""
    try:
        sigma = np.asarray(covariance, dtype=np.float64).reshape(6, 6)
    except (ValueError, TypeError):
        return math.inf
    if not np.all(np.isfinite(sigma)) or np.any(np.diag(sigma) < 0.0):
        return math.inf
    worst = 0.0
    for A in _worst_places(camera_height_m, reach_m):
        (p, q), (_, r) = A @ sigma @ A.T
        worst = max(worst, 0.5 * (p + r) + math.hypot(0.5 * (p - r), q))    # larger eigenvalue
    return math.sqrt(max(worst, 0.0))


@functools.lru_cache(maxsize=8)
def _worst_places(camera_height_m: float, reach_m: float) -> tuple:
    """ball_error_jacobian at the plate centre and the four corners of the ball's reach."""
    return tuple(ball_error_jacobian((x, y), camera_height_m)
                 for x, y in ((0.0, 0.0), (reach_m, reach_m), (-reach_m, reach_m), (reach_m, -reach_m),
                              (-reach_m, -reach_m)))
