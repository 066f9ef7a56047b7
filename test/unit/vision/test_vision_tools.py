"""Calibration YAML, the checkerboard calibration tool and the HSV tuning tool."""
import cv2
import numpy as np
import pytest

from ball_balance.tools import calibrate_camera, tune_hsv
from ball_balance.vision.camera import CalibrationError, CameraModel, Undistorter, load_calibration, save_calibration
from ball_balance.vision.synthetic import SyntheticScene, rotation_xy


def test_calibration_yaml_round_trip(tmp_path):
    K = np.array([[600.0, 0, 321.5], [0, 602.0, 238.0], [0, 0, 1]])
    model = CameraModel(640, 480, K, np.array([-0.2, 0.05, 0.001, -0.001, 0.0]), name="usb")
    save_calibration(str(tmp_path / "cam.yaml"), model)
    loaded = load_calibration(str(tmp_path / "cam.yaml"))
    np.testing.assert_allclose(loaded.K, K)
    np.testing.assert_allclose(loaded.D, model.D)
    assert (loaded.width, loaded.height, loaded.name) == (640, 480, "usb")
    text = (tmp_path / "cam.yaml").read_text()
    assert "camera_matrix:" in text and "projection_matrix:" in text and "distortion_model: plumb_bob" in text


def test_unusable_calibration_files_name_the_file(tmp_path):
    with pytest.raises(CalibrationError, match="does not exist"):
        load_calibration(str(tmp_path / "missing.yaml"))
    (tmp_path / "bad.yaml").write_text("image_width: 640\n")
    with pytest.raises(CalibrationError, match="bad.yaml"):
        load_calibration(str(tmp_path / "bad.yaml"))


def test_point_undistortion_inverts_the_distortion_model():
    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    D = np.array([-0.25, 0.08, 0.0, 0.0, 0.0])
    ideal = np.array([[100.0, 80.0], [320.0, 240.0], [600.0, 420.0]])
    rays = np.column_stack([(ideal - K[:2, 2]) / 500.0, np.ones(3)])
    distorted, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), K, D)
    np.testing.assert_allclose(Undistorter(CameraModel(640, 480, K, D)).points(distorted.reshape(-1, 2)), ideal,
                               atol=0.05)


def checkerboard_views(K, pattern=(9, 6), square_m=0.03):
    cols, rows = pattern[0] + 1, pattern[1] + 1
    px = 40
    board = np.kron((np.indices((rows, cols)).sum(axis=0) % 2).astype(np.uint8) * 255, np.ones((px, px), np.uint8))
    board = cv2.copyMakeBorder(board, px, px, px, px, cv2.BORDER_CONSTANT, value=255)
    # board pixel (j, i) -> board plane metres (origin at the first inner corner)
    T = np.array([[square_m / px, 0, -2 * square_m], [0, square_m / px, -2 * square_m], [0, 0, 1.0]])
    views = []
    for ax, ay, z in [(0.0, 0.0, 0.5), (0.35, 0.0, 0.55), (0.0, 0.35, 0.55), (-0.3, 0.25, 0.6), (0.25, -0.3, 0.6)]:
        R = rotation_xy(ax, ay)
        t = np.array([-0.12, -0.08, z])
        H = K @ np.column_stack([R[:, 0], R[:, 1], t]) @ T
        views.append(cv2.warpPerspective(board, H, (640, 480), borderValue=128))
    return views


def test_checkerboard_calibration_recovers_the_focal_length(tmp_path):
    K = np.array([[550.0, 0, 319.5], [0, 550.0, 239.5], [0, 0, 1]])
    for i, view in enumerate(checkerboard_views(K)):
        cv2.imwrite(str(tmp_path / f"view{i}.png"), view)
    out = tmp_path / "cam.yaml"
    code = calibrate_camera.main([str(tmp_path / "view*.png"), "--pattern", "9x6", "--square-m", "0.03",
                                  "--out", str(out)])
    assert code == 0
    model = load_calibration(str(out))
    assert model.K[0, 0] == pytest.approx(550.0, rel=0.02) and model.K[1, 1] == pytest.approx(550.0, rel=0.02)


def test_calibration_without_a_board_fails_with_one_line(tmp_path, capsys):
    cv2.imwrite(str(tmp_path / "blank.png"), np.full((100, 100), 128, np.uint8))
    code = calibrate_camera.main([str(tmp_path / "blank.png"), "--pattern", "9x6", "--square-m", "0.03",
                                  "--out", str(tmp_path / "cam.yaml")])
    assert code == 1 and "found in 0 of 1 images" in capsys.readouterr().err


def test_hsv_tuning_suggests_a_band_and_writes_previews(tmp_path, capsys):
    scene = SyntheticScene()
    image, _ = scene.render((0.05, 0.05))
    u, v = scene.camera.project(np.array([[0.05, 0.05, scene.ball_radius_m]]))[0]
    cv2.imwrite(str(tmp_path / "frame.png"), image)
    code = tune_hsv.main([str(tmp_path / "frame.png"), "--out", str(tmp_path / "hsv"), "--pick", str(int(u)),
                          str(int(v))])
    printed = capsys.readouterr().out
    assert code == 0 and "hsv_lower:" in printed and "ball at" in printed
    mask = cv2.imread(str(tmp_path / "hsv" / "mask.png"), 0)
    assert mask[int(v), int(u)] == 255 and mask[10, 10] == 0
    assert (tmp_path / "hsv" / "overlay.png").exists()
