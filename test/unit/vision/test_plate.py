"""Plate homography from ArUco markers, against synthetic frames with known geometry."""
import cv2
import numpy as np
import pytest

from ball_balance.plate_geometry import PlateGeometry
from ball_balance.vision.plate import (
    MarkerDetector,
    PlateLocator,
    apply_homography,
    camera_centre_in_plate,
    estimate_focal_px,
)
from ball_balance.vision.synthetic import SyntheticCamera, SyntheticScene


def gray(image):
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


def test_marker_corners_m_is_opencv_corner_order_on_a_real_detection():
    scene = SyntheticScene(SyntheticCamera(camera_offset_m=(0.02, -0.01), camera_tilt_rad=(0.04, -0.03)))
    image, truth = scene.render(None)
    found = MarkerDetector().detect(gray(image))
    assert sorted(found) == [0, 1, 2, 3]
    geometry = PlateGeometry()
    for marker_id, corners_px in found.items():
        corners_P = np.array(geometry.marker_corners_m(marker_id))
        expected_px = apply_homography(truth["H_IP"], corners_P)
        assert np.max(np.linalg.norm(corners_px - expected_px, axis=1)) < 1.0, marker_id


def lock(locator, image, frames):
    for i in range(frames):
        locator.update(locator.find_markers(gray(image)), i / 30.0)


def test_locks_only_after_startup_frames_with_all_markers_then_matches_truth():
    scene = SyntheticScene()
    image, truth = scene.render(None, noise_std=2.0)
    locator = PlateLocator(PlateGeometry(), startup_frames=5)
    lock(locator, image, 4)
    assert not locator.locked
    lock(locator, image, 1)
    assert locator.locked
    plate_pts = np.array([[-0.2, -0.2], [0.2, 0.1], [0.0, 0.0]])
    error_px = apply_homography(locator.H_IP, plate_pts) - apply_homography(truth["H_IP"], plate_pts)
    assert np.max(np.abs(error_px)) < 0.75


def test_startup_restarts_while_the_plate_moves_but_locks_eventually():
    camera = SyntheticCamera()
    scene = SyntheticScene(camera)
    locator = PlateLocator(PlateGeometry(), startup_frames=4, startup_max_motion_px=1.0)
    for i in range(11):                             # rocking: never 4 steady frames in a row
        camera.set_plate_tilt(0.03 * (-1) ** i, 0.0)
        lock(locator, scene.render(None)[0], 1)
        assert not locator.locked, i
    camera.set_plate_tilt(0.01, 0.0)
    image, truth = scene.render(None)
    lock(locator, image, 1)                          # 3 x startup_frames frames seen: locks
    assert locator.locked
    np.testing.assert_allclose(apply_homography(locator.H_IP, np.zeros((1, 2))),
                               apply_homography(truth["H_IP"], np.zeros((1, 2))), atol=0.5)


def test_startup_needs_all_markers():
    scene = SyntheticScene()
    image, _ = scene.render(None, occlude=[2])
    locator = PlateLocator(PlateGeometry(), startup_frames=3)
    lock(locator, image, 10)
    assert not locator.locked


@pytest.mark.parametrize("with_intrinsics", [True, False], ids=["pivot_pose_fit", "shift_only"])
@pytest.mark.parametrize("visible", [[3], [0, 1], [0, 3], [0, 1, 2]])
def test_refit_from_any_visible_markers_after_the_plate_tilted(visible, with_intrinsics):
    camera = SyntheticCamera()
    scene = SyntheticScene(camera)
    locator = PlateLocator(PlateGeometry(), startup_frames=3)
    if with_intrinsics:
        locator.set_intrinsics(camera.K)
    lock(locator, scene.render(None)[0], 3)
    camera.set_plate_tilt(0.04, -0.03)           # the plate tilts about its centre
    image, truth = scene.render(None, occlude=[m for m in range(4) if m not in visible])
    markers = locator.find_markers(gray(image))
    assert sorted(markers) == visible
    locator.update(markers, 1.0)
    plate_pts = np.array([[x, y] for x in (-0.2, 0.0, 0.2) for y in (-0.2, 0.0, 0.2)])
    error_px = np.max(np.linalg.norm(apply_homography(locator.H_IP, plate_pts)
                                     - apply_homography(truth["H_IP"], plate_pts), axis=1))
    # about 0.9 px per mm here. Without intrinsics 1-2 markers only shift the start-up fit:
    # the tilt's perspective change is not seen (several px)
    if len(visible) >= 3:
        assert error_px < 1.0
    elif with_intrinsics:     # one marker: the tilt about the axis through it stays unseen
        assert error_px < (2.0 if len(visible) == 1 else 1.0)
    else:
        assert error_px > 2.0


def test_plate_held_for_hold_time_when_no_marker_is_visible():
    scene = SyntheticScene()
    locator = PlateLocator(PlateGeometry(), startup_frames=2, plate_hold_s=0.2)
    lock(locator, scene.render(None)[0], 2)
    empty = scene.render(None, occlude=[0, 1, 2, 3])[0]
    assert locator.update(locator.find_markers(gray(empty)), 0.1 + 1 / 30) is False
    assert locator.plate_visible(0.2)
    assert not locator.plate_visible(0.3)


def test_focal_length_and_camera_centre_from_an_oblique_view():
    camera = SyntheticCamera(camera_offset_m=(0.04, -0.03), camera_tilt_rad=(0.08, 0.05))
    centre = ((camera.width - 1) / 2, (camera.height - 1) / 2)
    assert estimate_focal_px(camera.H_IP, centre) == pytest.approx(camera.K[0, 0], rel=1e-6)
    np.testing.assert_allclose(camera_centre_in_plate(camera.H_IP, camera.K), camera.C_P, atol=1e-9)


def test_focal_length_unknown_from_a_fronto_parallel_view():
    camera = SyntheticCamera()
    assert estimate_focal_px(camera.H_IP, ((camera.width - 1) / 2, (camera.height - 1) / 2)) is None


class _FindsNothing:
    def detectMarkers(self, image):
        return (), None, ()


def test_marker_windows_use_one_threshold_pass_and_all_passes_where_it_misses():
    image, truth = SyntheticScene().render(None, noise_std=2.0)
    locator = PlateLocator(PlateGeometry(), startup_frames=3)
    lock(locator, image, 3)
    windows = locator._windows(image.shape)
    detector = locator.detector
    one_pass = detector.detect_in_windows(image, windows)
    assert sorted(one_pass) == [0, 1, 2, 3] and detector.window_fallbacks == 0
    detector._window_detector = _FindsNothing()          # the single pass misses every marker
    all_passes = detector.detect_in_windows(image, windows)
    assert sorted(all_passes) == [0, 1, 2, 3] and detector.window_fallbacks == 4
    for marker_id, corners_px in all_passes.items():
        expected_px = apply_homography(truth["H_IP"], np.array(PlateGeometry().marker_corners_m(marker_id)))
        assert np.max(np.linalg.norm(corners_px - expected_px, axis=1)) < 1.0
        assert np.max(np.abs(corners_px - one_pass[marker_id])) < 0.05
