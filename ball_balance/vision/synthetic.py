"""Synthetic camera frames with known truth: the plate with its ArUco markers, seen by a
pinhole camera, and the orange ball ray-traced as a sphere resting on the plate.

For tests and benchmarks (no simulator needed). Plate frame as docs/design.md section 5; the
ball's centre is at z = ball radius. The camera looks down at the plate from C_P.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, Optional, Sequence, Tuple

import cv2
import numpy as np

from ball_balance.plate_geometry import BALL_RADIUS_M, PlateGeometry

BALL_BGR = (0, 110, 255)        # orange (OpenCV hue ~13)
PLATE_GREY = 235
BACKGROUND_GREY = 45


def rotation_xy(about_x_rad: float, about_y_rad: float) -> np.ndarray:
    """R = Rx(about_x) @ Ry(about_y)."""
    cx, sx, cy, sy = np.cos(about_x_rad), np.sin(about_x_rad), np.cos(about_y_rad), np.sin(about_y_rad)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    return Rx @ Ry


@dataclass
class SyntheticCamera:
    """A pinhole camera above the plate. `camera_height_m=None` fits the plate to 90 % of the
    image height; `camera_offset_m` moves the camera sideways; `camera_tilt_rad` (about the
    plate x, y axes) makes the view oblique."""

    width: int = 640
    height: int = 480
    hfov_deg: float = 60.0
    camera_height_m: Optional[float] = None
    camera_offset_m: Tuple[float, float] = (0.0, 0.0)
    camera_tilt_rad: Tuple[float, float] = (0.0, 0.0)
    geometry: PlateGeometry = field(default_factory=PlateGeometry)

    def __post_init__(self):
        f = 0.5 * self.width / np.tan(np.radians(self.hfov_deg) / 2.0)
        self.K = np.array([[f, 0.0, (self.width - 1) / 2.0], [0.0, f, (self.height - 1) / 2.0], [0, 0, 1.0]])
        if self.camera_height_m is None:
            self.camera_height_m = f * self.geometry.side_m / (0.9 * self.height)
        self.set_plate_tilt(0.0, 0.0)

    def set_plate_tilt(self, about_x_rad: float, about_y_rad: float) -> None:
        """Tilt the plate under the fixed camera (a rotation about the plate centre)."""
        R_WP = rotation_xy(about_x_rad, about_y_rad)                  # world <- plate
        R_CW = np.diag([1.0, -1.0, -1.0]) @ rotation_xy(*self.camera_tilt_rad).T  # camera <- world
        C_W = np.array([*self.camera_offset_m, self.camera_height_m])
        self.R_CP = R_CW @ R_WP
        self.C_P = R_WP.T @ C_W                                        # camera centre, plate frame
        self.t_CP = -self.R_CP @ self.C_P
        self.H_IP = self.K @ np.column_stack([self.R_CP[:, 0], self.R_CP[:, 1], self.t_CP])
        self.H_IP /= self.H_IP[2, 2]

    def project(self, points_P: np.ndarray) -> np.ndarray:
        """Plate-frame points (n, 3) -> pixels (n, 2)."""
        X_C = np.asarray(points_P, dtype=np.float64) @ self.R_CP.T + self.t_CP
        uv = X_C @ self.K.T
        return uv[:, :2] / uv[:, 2:3]


class SyntheticScene:
    """Renders frames of the plate, markers and ball for one `SyntheticCamera`."""

    def __init__(self, camera: Optional[SyntheticCamera] = None, texture_px_per_m: Optional[float] = None,
                 ball_radius_m: float = BALL_RADIUS_M):
        self.camera = camera or SyntheticCamera()
        self.geometry = self.camera.geometry
        self.ball_radius_m = ball_radius_m
        # default: about one texture pixel per image pixel (little aliasing)
        self.texture_px_per_m = texture_px_per_m or self.camera.K[0, 0] / self.camera.camera_height_m
        self.texture = self._plate_texture()

    def _plate_texture(self) -> np.ndarray:
        """The plate seen from above: texture pixel (i, j) <-> plate (x, y), y up."""
        s = self.texture_px_per_m
        n = int(round(self.geometry.side_m * s))
        tex = np.full((n, n), PLATE_GREY, np.uint8)
        dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
        side_px = int(round(self.geometry.marker_side_m * s))
        for marker_id, x, y in self.geometry.marker_centres_m:
            marker = cv2.aruco.generateImageMarker(dictionary, marker_id, side_px)   # top of image = +y
            col = int(round((x + self.geometry.side_m / 2) * s - side_px / 2))
            row = int(round((self.geometry.side_m / 2 - y) * s - side_px / 2))
            tex[row:row + side_px, col:col + side_px] = marker
        return cv2.cvtColor(tex, cv2.COLOR_GRAY2BGR)

    def _H_image_from_texture(self) -> np.ndarray:
        s, half = self.texture_px_per_m, self.geometry.side_m / 2.0
        # texture pixel centre (j, i) -> plate (x, y) = ((j + 0.5) / s - half, half - (i + 0.5) / s)
        T_PT = np.array([[1.0 / s, 0.0, 0.5 / s - half], [0.0, -1.0 / s, half - 0.5 / s], [0.0, 0.0, 1.0]])
        return self.camera.H_IP @ T_PT

    def render(self, ball_xy_m: Optional[Tuple[float, float]], noise_std: float = 0.0, blur_px: int = 0,
               occlude: Sequence[int] = (), rng: Optional[np.random.Generator] = None,
               supersample: int = 4) -> Tuple[np.ndarray, Dict]:
        """One BGR frame and its truth (ball_xy_m, H_IP, marker corners in pixels)."""
        cam = self.camera
        image = cv2.warpPerspective(self.texture, self._H_image_from_texture(), (cam.width, cam.height),
                                    flags=cv2.INTER_AREA, borderValue=(BACKGROUND_GREY,) * 3)
        truth = {"ball_xy_m": ball_xy_m, "H_IP": cam.H_IP.copy(), "markers_px": {}}
        for marker_id, _, _ in self.geometry.marker_centres_m:
            corners_P = np.array(self.geometry.marker_corners_m(marker_id))
            truth["markers_px"][marker_id] = cam.project(np.column_stack([corners_P, np.zeros(4)]))
        for marker_id in occlude:                      # a grey "hand" over the marker
            c = truth["markers_px"][marker_id]
            centre, side = c.mean(axis=0), np.ptp(c, axis=0).max()
            cv2.circle(image, tuple(int(round(v)) for v in centre), int(side * 0.9), (120, 130, 140), -1)
        if ball_xy_m is not None:
            self._draw_ball(image, ball_xy_m, supersample)
        if blur_px:
            image = cv2.GaussianBlur(image, (0, 0), blur_px / 2.0)
        if noise_std:
            rng = rng or np.random.default_rng(0)
            noisy = image.astype(np.float32) + rng.normal(0.0, noise_std, image.shape).astype(np.float32)
            image = np.clip(noisy, 0, 255).astype(np.uint8)
        return image, truth

    def _draw_ball(self, image: np.ndarray, ball_xy_m, supersample: int) -> None:
        """Ray-trace the sphere (anti-aliased by supersampling, Lambert-shaded)."""
        cam, r = self.camera, self.ball_radius_m
        S_P = np.array([ball_xy_m[0], ball_xy_m[1], r])
        centre_px = cam.project(S_P[None])[0]
        depth = np.linalg.norm(S_P - cam.C_P)
        reach = cam.K[0, 0] * r / depth * 1.5 + 2
        x0, y0 = np.floor(centre_px - reach).astype(int)
        x1, y1 = np.ceil(centre_px + reach).astype(int)
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, cam.width), min(y1, cam.height)
        if x1 <= x0 or y1 <= y0:
            return
        k = supersample
        offsets = (np.arange(k) + 0.5) / k - 0.5
        us = (np.arange(x0, x1)[:, None] + offsets[None]).ravel()
        vs = (np.arange(y0, y1)[:, None] + offsets[None]).ravel()
        U, V = np.meshgrid(us, vs)
        rays_C = np.stack([U, V, np.ones_like(U)], axis=-1) @ np.linalg.inv(cam.K).T
        d = rays_C @ cam.R_CP                     # ray directions in the plate frame (R_PC = R_CP^T)
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        oc = cam.C_P - S_P
        b = d @ oc
        disc = b * b - (oc @ oc - r * r)
        hit = disc >= 0.0
        t = -b - np.sqrt(np.where(hit, disc, 0.0))
        normal = (cam.C_P + t[..., None] * d - S_P) / r
        light = np.array([0.3, 0.3, 0.9]) / np.linalg.norm([0.3, 0.3, 0.9])
        shade = np.where(hit, 0.75 + 0.25 * np.clip(normal @ light, 0.0, 1.0), 0.0)
        h, w = y1 - y0, x1 - x0
        coverage = hit.reshape(h, k, w, k).mean(axis=(1, 3))[..., None]
        shade = shade.reshape(h, k, w, k).sum(axis=(1, 3))[..., None] / np.maximum(
            hit.reshape(h, k, w, k).sum(axis=(1, 3))[..., None], 1)
        patch = image[y0:y1, x0:x1].astype(np.float32)
        colour = np.array(BALL_BGR, np.float32) * shade
        image[y0:y1, x0:x1] = np.clip(patch * (1.0 - coverage) + colour * coverage, 0, 255).astype(np.uint8)
