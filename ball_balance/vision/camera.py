"""Camera intrinsics and distortion: the ROS camera_info YAML format, and undistortion.

The YAML is the one `camera_calibration` writes and `camera_calibration_parsers` reads
(image_width, image_height, camera_name, camera_matrix, distortion_model,
distortion_coefficients, rectification_matrix, projection_matrix; matrices as
{rows, cols, data}). Only `plumb_bob` / `rational_polynomial` distortion (OpenCV's model).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

import cv2
import numpy as np
import yaml


class CalibrationError(ValueError):
    """A calibration file that cannot be used (the message names the file and the problem)."""


@dataclass(frozen=True)
class CameraModel:
    """Pinhole intrinsics K (3x3, pixels) and OpenCV distortion coefficients D."""

    width: int
    height: int
    K: np.ndarray
    D: np.ndarray
    distortion_model: str = "plumb_bob"
    name: str = "camera"

    @property
    def distorted(self) -> bool:
        return bool(np.any(self.D != 0.0))

    @classmethod
    def from_camera_info(cls, width: int, height: int, k: Sequence[float], d: Sequence[float],
                         distortion_model: str = "plumb_bob") -> Optional[CameraModel]:
        """From sensor_msgs/CameraInfo fields; None when K is all zeros (uncalibrated)."""
        K = np.array(k, dtype=np.float64).reshape(3, 3)
        if K[0, 0] <= 0.0 or K[1, 1] <= 0.0:
            return None
        return cls(int(width), int(height), K, np.array(d, dtype=np.float64).ravel(), distortion_model or "plumb_bob")

    @classmethod
    def pinhole(cls, width: int, height: int, fx: float, fy: float, cx: float, cy: float) -> CameraModel:
        """An ideal camera (no distortion), e.g. the simulation's rendered one."""
        return cls(int(width), int(height), np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]), np.zeros(5))

    def scaled_to(self, width: int, height: int) -> CameraModel:
        """The same camera at another resolution (same field of view)."""
        if (width, height) == (self.width, self.height):
            return self
        S = np.diag([width / self.width, height / self.height, 1.0])
        return CameraModel(width, height, S @ self.K, self.D, self.distortion_model, self.name)


def load_calibration(path: str) -> CameraModel:
    """Read a ROS camera_info YAML; CalibrationError with one clear line when it is unusable."""
    file = Path(path)
    if not file.is_file():
        raise CalibrationError(f"calibration file '{path}' does not exist")
    try:
        data = yaml.safe_load(file.read_text())
        K = np.array(data["camera_matrix"]["data"], dtype=np.float64).reshape(3, 3)
        D = np.array(data.get("distortion_coefficients", {}).get("data", []) or [], dtype=np.float64)
        model = CameraModel(int(data["image_width"]), int(data["image_height"]), K, D,
                            str(data.get("distortion_model", "plumb_bob")), str(data.get("camera_name", "camera")))
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError) as error:
        raise CalibrationError(f"calibration file '{path}' is not a camera_info YAML: "
                               f"{type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''}") from None
    if model.distortion_model not in ("plumb_bob", "rational_polynomial"):
        raise CalibrationError(f"calibration file '{path}': distortion_model '{model.distortion_model}' unsupported")
    if K[0, 0] <= 0 or K[1, 1] <= 0 or model.width <= 0 or model.height <= 0:
        raise CalibrationError(f"calibration file '{path}': focal lengths and image size must be positive")
    return model


def save_calibration(path: str, model: CameraModel) -> None:
    """Write `model` as a ROS camera_info YAML (projection = [K | 0], no rectification)."""
    def matrix(rows, cols, values):
        return {"rows": rows, "cols": cols, "data": [float(v) for v in np.ravel(values)]}

    P = np.hstack([model.K, np.zeros((3, 1))])
    data = {
        "image_width": int(model.width), "image_height": int(model.height), "camera_name": model.name,
        "camera_matrix": matrix(3, 3, model.K), "distortion_model": model.distortion_model,
        "distortion_coefficients": matrix(1, len(model.D), model.D),
        "rectification_matrix": matrix(3, 3, np.eye(3)), "projection_matrix": matrix(3, 4, P),
    }
    Path(path).write_text(yaml.safe_dump(data, sort_keys=False))


class Undistorter:
    """Removes lens distortion, either from whole images (remap tables built once) or only
    from the few points the tracker measures (much cheaper). Output pixels follow the same
    K (an ideal pinhole camera with the calibration's intrinsics)."""

    def __init__(self, model: CameraModel, mode: str = "points"):
        self.model, self.mode = model, mode
        self._maps = None
        if mode == "image" and model.distorted:
            self._maps = cv2.initUndistortRectifyMap(model.K, model.D, None, model.K,
                                                     (model.width, model.height), cv2.CV_16SC2)

    def image(self, image: np.ndarray) -> np.ndarray:
        if self._maps is None:
            return image
        return cv2.remap(image, self._maps[0], self._maps[1], cv2.INTER_LINEAR)

    def points(self, pixels: np.ndarray) -> np.ndarray:
        """(n, 2) distorted pixels -> undistorted pixels (identity in image mode)."""
        if self.mode == "image" or not self.model.distorted:
            return pixels
        p = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
        return cv2.undistortPoints(p, self.model.K, self.model.D, P=self.model.K).reshape(-1, 2)
