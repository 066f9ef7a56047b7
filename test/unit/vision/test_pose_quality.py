"""Plate pose covariance and the ball-position error it causes (ball_balance.vision.pose_quality)."""
import math

import cv2
import numpy as np
import pytest

from ball_balance.plate_geometry import BALL_RADIUS_M, PlateGeometry
from ball_balance.vision import pose_quality as pq
from ball_balance.vision.camera import CameraModel
from ball_balance.vision.config import TrackerConfig
from ball_balance.vision.plate import apply_homography, camera_centre_in_plate, fit_pose_with_pivot_prior
from ball_balance.vision.synthetic import SyntheticCamera, SyntheticScene
from ball_balance.vision.tracker import PRIOR_INFORMATION, BallTracker

GEOMETRY = PlateGeometry()


def corners(ids):
    return np.concatenate([np.array(GEOMETRY.marker_corners_m(m)) for m in ids])


def test_projection_jacobian_matches_finite_differences():
    camera = SyntheticCamera()
    camera.set_plate_tilt(0.1, -0.05)
    pts = corners(range(4))

    def project(x):         # the module's perturbation: exp([dphi]x) R X + t + dt
        R = cv2.Rodrigues(x[3:])[0] @ camera.R_CP
        X = np.column_stack([pts, np.zeros(len(pts))]) @ R.T + camera.t_CP + x[:3]
        q = X @ camera.K.T
        return (q[:, :2] / q[:, 2:]).ravel()

    numeric = np.column_stack([(project(e * 1e-7) - project(-e * 1e-7)) / 2e-7 for e in np.eye(6)])
    J = pq.projection_jacobian(pts, camera.K, camera.R_CP, camera.t_CP)
    assert np.allclose(J, numeric, atol=1e-4 * np.abs(J).max())


@pytest.mark.parametrize("visible", [[0, 1, 2, 3], [0, 1, 2], [0, 1], [0]], ids=["4", "3", "2", "1"])
def test_predicted_ball_error_agrees_with_monte_carlo_corner_noise(visible):
    """Corners with 0.5 px noise, the tracker's pose fit, the ball mapped at the plate corner:
    the spread agrees with the covariance's prediction (within 25 % either way, 1 marker:
    the linear model is conservative)."""
    camera = SyntheticCamera(camera_height_m=pq.DEFAULT_CAMERA_HEIGHT_M)
    ball = np.array([pq.DEFAULT_REACH_M, pq.DEFAULT_REACH_M, BALL_RADIUS_M])
    uv = apply_homography(camera.K @ np.column_stack([camera.R_CP[:, 0], camera.R_CP[:, 1],
                                                      camera.R_CP @ ball + camera.t_CP]), [[0.0, 0.0]])
    pts = corners(visible)
    truth_px = apply_homography(camera.H_IP, pts)
    rng = np.random.default_rng(3)
    sigma_px = 0.5
    errors = []
    for _ in range(300):
        H = fit_pose_with_pivot_prior(pts, truth_px + rng.normal(0.0, sigma_px, truth_px.shape), camera.K,
                                      camera.R_CP, camera.t_CP)
        C = camera_centre_in_plate(H, camera.K)
        p = apply_homography(np.linalg.inv(H), uv)[0]
        s = (C[2] - BALL_RADIUS_M) / C[2]
        errors.append(C[:2] + s * (p - C[:2]) - ball[:2])
    measured = np.sqrt(np.mean(np.square(errors), axis=0))
    prior = None if len(visible) == 4 else PRIOR_INFORMATION
    covariance = pq.pose_covariance(pts, camera.K, camera.R_CP, camera.t_CP, sigma_px, prior)
    A = pq.ball_error_jacobian(ball[:2])
    predicted = np.sqrt(np.diag(A @ covariance @ A.T))
    assert np.all(measured > 0.5 * predicted) if len(visible) == 1 else np.all(measured > 0.75 * predicted)
    assert np.all(measured < 1.25 * predicted)


def test_ball_position_std_takes_the_message_layout_and_refuses_unusable_covariances():
    covariance = np.diag([1e-8, 1e-8, 4e-8, 1e-6, 1e-6, 1e-7])
    std = pq.ball_position_std_m(covariance.ravel().tolist())       # PoseWithCovariance.covariance
    assert std == pq.ball_position_std_m(covariance) and 1e-4 < std < 1e-3
    assert pq.ball_position_std_m(np.zeros((6, 6))) == 0.0
    assert pq.ball_position_std_m(pq.UNUSABLE_COVARIANCE) == math.inf
    assert pq.ball_position_std_m([float("nan")] * 36) == math.inf
    assert pq.ball_position_std_m([0.0] * 35) == math.inf
    assert pq.ball_position_std_m(-covariance) == math.inf


def test_in_plane_translation_error_is_the_ball_error_and_rotation_error_grows_with_reach():
    sigma_t = np.diag([1e-6, 1e-6, 0.0, 0.0, 0.0, 0.0])              # 1 mm in camera x and y
    assert pq.ball_position_std_m(sigma_t) == pytest.approx(1e-3, rel=0.02)
    spin = np.diag([0.0] * 5 + [1e-4])                                # 10 mrad about the optical axis
    assert pq.ball_position_std_m(spin, reach_m=0.2) == pytest.approx(0.01 * 0.2 * math.sqrt(2), rel=0.02)
    assert pq.ball_position_std_m(spin, reach_m=0.1) < pq.ball_position_std_m(spin, reach_m=0.2)


def tracker_on(scene, calibrated=True):
    camera = scene.camera
    model = CameraModel(camera.width, camera.height, camera.K, np.zeros(5)) if calibrated else None
    tracker = BallTracker(TrackerConfig.from_values({"startup_frames": 3}), model)
    for i in range(4):
        tracker.process(scene.render((0.05, 0.02))[0], i / 30.0)
    return tracker


@pytest.mark.parametrize("calibrated", [True, False], ids=["intrinsics", "no_intrinsics"])
def test_tracker_reports_a_pose_whose_quality_falls_with_each_hidden_marker(calibrated):
    scene = SyntheticScene(SyntheticCamera())
    tracker = tracker_on(scene, calibrated)
    scene.camera.set_plate_tilt(0.03, -0.02)
    stds = []
    for hidden in ([], [3], [2, 3], [1, 2, 3]):
        result = tracker.process(scene.render((0.05, 0.02), occlude=hidden)[0], 1.0 + len(hidden) / 30.0)
        assert result.markers_found == 4 - len(hidden)
        R_CP, t_CP = result.plate_pose
        assert result.pose_covariance.shape == (6, 6)
        assert result.position_std_m == pq.ball_position_std_m(result.pose_covariance)
        if calibrated:
            assert np.allclose(t_CP, scene.camera.t_CP, atol=0.01)
            assert np.allclose(R_CP, scene.camera.R_CP, atol=0.02)
        stds.append(result.position_std_m)
    assert all(0.0 < std < 0.02 for std in stds)
    assert stds == sorted(stds) and stds[0] < 0.5e-3 and stds[3] > 2 * stds[0]


def test_no_markers_or_no_lock_means_no_usable_pose():
    scene = SyntheticScene(SyntheticCamera())
    tracker = BallTracker(TrackerConfig.from_values({"startup_frames": 3}), None)
    first = tracker.process(scene.render((0.0, 0.0))[0], 0.0)
    assert first.markers_found == 4 and first.position_std_m == math.inf and first.plate_pose is None
    tracker = tracker_on(scene)
    hidden = tracker.process(scene.render((0.0, 0.0), occlude=[0, 1, 2, 3])[0], 0.2)
    assert hidden.plate_visible and hidden.position_std_m == math.inf and hidden.pose_covariance is None
