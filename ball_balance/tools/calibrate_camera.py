"""Calibrate a camera from checkerboard images into the camera_info YAML the tracker reads.

    python -m ball_balance.tools.calibrate_camera 'shots/*.png' --pattern 9x6 --square-m 0.025 \\
        --out config/usb_camera.yaml

`--pattern` counts inner corners (columns x rows). Take 10-20 views, tilted and spread over
the image. Prints the RMS reprojection error (good: < 0.5 px); the tracker uses the file with
`calibration_file:=config/usb_camera.yaml`. Any images OpenCV reads will do (grab them with
your camera app, or record the camera topic with `camera_snapshot`).
"""
from __future__ import annotations

import argparse
import glob
import sys
from typing import List, Sequence, Tuple

import cv2
import numpy as np

from ball_balance.vision.camera import CameraModel, save_calibration

MIN_VIEWS = 3


class CalibrationFailed(RuntimeError):
    pass


def find_corners(images: Sequence[np.ndarray], pattern: Tuple[int, int]) -> List[np.ndarray]:
    """Sub-pixel inner corners (n, 1, 2) per image where the whole pattern is found."""
    found = []
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    for image in images:
        gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
        ok, corners = cv2.findChessboardCorners(gray, pattern, cv2.CALIB_CB_ADAPTIVE_THRESH |
                                                cv2.CALIB_CB_NORMALIZE_IMAGE)
        if ok:
            found.append(cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1), criteria))
    return found


def calibrate(images: Sequence[np.ndarray], pattern: Tuple[int, int], square_m: float,
              name: str = "camera") -> Tuple[CameraModel, float, int]:
    """(camera model, RMS reprojection error in px, views used) from checkerboard images."""
    if not images:
        raise CalibrationFailed("no images")
    height, width = images[0].shape[:2]
    corners = find_corners(images, pattern)
    if len(corners) < MIN_VIEWS:
        raise CalibrationFailed(f"checkerboard {pattern[0]}x{pattern[1]} found in {len(corners)} of "
                                f"{len(images)} images, need {MIN_VIEWS}")
    board = np.zeros((pattern[0] * pattern[1], 3), np.float32)
    board[:, :2] = np.mgrid[0:pattern[0], 0:pattern[1]].T.reshape(-1, 2) * square_m
    rms, K, D, _, _ = cv2.calibrateCamera([board] * len(corners), corners, (width, height), None, None)
    return CameraModel(width, height, K, D.ravel(), "plumb_bob", name), float(rms), len(corners)


def _pattern(text: str) -> Tuple[int, int]:
    try:
        cols, rows = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--pattern '{text}' must be COLSxROWS, e.g. 9x6") from None
    return cols, rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("images", nargs="+", help="image files or glob patterns")
    parser.add_argument("--pattern", type=_pattern, required=True, help="inner corners, COLSxROWS")
    parser.add_argument("--square-m", type=float, required=True, help="checkerboard square side (m)")
    parser.add_argument("--out", required=True, help="camera_info YAML to write")
    parser.add_argument("--name", default="camera", help="camera_name in the YAML")
    args = parser.parse_args(argv)
    paths = sorted({p for pattern in args.images for p in (glob.glob(pattern) or [pattern])})
    images = [cv2.imread(p) for p in paths]
    unreadable = [p for p, image in zip(paths, images) if image is None]
    if unreadable:
        print(f"calibrate_camera: cannot read image '{unreadable[0]}'", file=sys.stderr)
        return 2
    try:
        model, rms, used = calibrate(images, args.pattern, args.square_m, args.name)
    except CalibrationFailed as error:
        print(f"calibrate_camera: {error}", file=sys.stderr)
        return 1
    save_calibration(args.out, model)
    print(f"{used} views, RMS reprojection error {rms:.3f} px, fx={model.K[0, 0]:.1f} fy={model.K[1, 1]:.1f} "
          f"cx={model.K[0, 2]:.1f} cy={model.K[1, 2]:.1f} -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
