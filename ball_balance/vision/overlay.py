"""Debug overlay: markers, plate outline, ball and velocity drawn on a copy of the frame."""
from __future__ import annotations

import cv2
import numpy as np

from ball_balance.vision.plate import PlateLocator, apply_homography
from ball_balance.vision.tracker import TrackerResult

GREEN, BLUE, RED, YELLOW = (0, 200, 0), (255, 120, 0), (0, 0, 255), (0, 220, 220)


def draw_overlay(image_bgr: np.ndarray, plate: PlateLocator, result: TrackerResult,
                 velocity_scale_s: float = 0.3) -> np.ndarray:
    """A copy of `image_bgr` with this frame's detections; velocity arrow = v * scale (m)."""
    out = image_bgr.copy()
    for marker_id, corners in plate.markers.items():
        cv2.polylines(out, [np.round(corners).astype(np.int32)], True, GREEN, 1)
        cv2.putText(out, str(marker_id), tuple(np.round(corners[0]).astype(int)), cv2.FONT_HERSHEY_SIMPLEX,
                    0.4, GREEN, 1)
    if plate.H_IP is not None:
        half = plate.geometry.side_m / 2.0
        outline = apply_homography(plate.H_IP, np.array([[-half, -half], [half, -half], [half, half], [-half, half]]))
        cv2.polylines(out, [np.round(outline).astype(np.int32)], True, BLUE, 1)
        if result.tracking_valid:
            ends = apply_homography(plate.H_IP, np.array([
                [result.x, result.y],
                [result.x + result.vx * velocity_scale_s, result.y + result.vy * velocity_scale_s]]))
            a, b = (tuple(int(round(c)) for c in p) for p in ends)
            cv2.circle(out, a, 3, YELLOW if result.ball_found else RED, -1)
            cv2.arrowedLine(out, a, b, YELLOW, 1)
    if result.blob is not None:
        centre = (int(round(result.blob.u)), int(round(result.blob.v)))
        cv2.circle(out, centre, int(round(result.blob.radius_px)), RED, 1)
    cv2.putText(out, f"markers {result.markers_found} found {int(result.ball_found)} valid "
                f"{int(result.tracking_valid)}", (5, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.45, RED, 1)
    return out
