"""The ball tracker pipeline: one BGR frame + its capture stamp -> the ball's plate-frame state.

Stages (each timed, see `STAGES`): optional undistortion of the image, ArUco marker
search, plate homography, ball segmentation (in a window around the last frame's blob,
the plate's whole image region when there was none or the ball left that window) with
mapping to plate metres, Kalman filter. Pure Python + OpenCV + numpy, no ROS.

Parallax: the camera sees the ball's centre 20 mm above the plate, so the plate-plane
homography alone would put it too far from the point under the camera (by r/C_z of the
distance, several mm at the plate edge). With intrinsics K (calibration file, camera_info,
or estimated from an oblique view of the plate) the camera centre C_P is recovered from
the homography and the ray is intersected with the plane z = r instead.

Delay: with `estimate_plate_cmd_delay` each frame's plate pose also gives the plate's tilt,
aligned with the /plate_cmd history to measure how long after a command the plate follows it
(ball_balance.vision.kalman.CommandDelayFromTilt); the filter's known acceleration and tilt
lever then use the command in force that long before the frame.

Pose quality: each frame with markers also yields the plate pose in the camera and its
covariance from the corner fit (`ball_balance.vision.pose_quality`), reduced to
`position_std_m`, the ball-position error that pose can cause (math.inf without markers).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Dict, Optional, Tuple

import numpy as np

from ball_balance.plate_geometry import GRAVITY_M_S2
from ball_balance.vision.ball_segmentation import BallBlob, BallSegmenter
from ball_balance.vision.camera import CameraModel, Undistorter
from ball_balance.vision.config import TrackerConfig
from ball_balance.vision.kalman import BallKalman, CommandDelayFromTilt, KalmanConfig, PlateCommandInput
from ball_balance.vision.plate import (
    FULL_FIT_MIN_MARKERS,
    PIVOT_PRIOR_SIGMA_ROT_RAD,
    PIVOT_PRIOR_SIGMA_T_M,
    PlateLocator,
    apply_homography,
    estimate_focal_px,
)
from ball_balance.vision.pose_quality import ball_position_std_m, pose_covariance

# without calibration or an estimate from an oblique view, the pose covariance assumes a
# 60 degree horizontal field of view (f = 0.866 x width); the figure scales little with it
NOMINAL_FOCAL_PER_WIDTH = 0.5 / math.tan(math.radians(30.0))
PRIOR_INFORMATION = np.diag([PIVOT_PRIOR_SIGMA_T_M ** -2] * 3 + [PIVOT_PRIOR_SIGMA_ROT_RAD ** -2] * 3)

# once the ball was found, the next frame is segmented only in a square around it, this many
# largest ball radii from its centre (~1/6 of the plate's image region at the default radius
# range): the ball may move 2 radii per frame before the whole plate must be searched again
BALL_WINDOW_RADII = 3.0

STAGES = ("undistort", "markers", "homography", "ball", "filter", "total")


@dataclass
class TrackerResult:
    """One frame's output; fields map 1:1 onto ball_tracker_msgs/BallState."""

    stamp_s: float
    x: float = 0.0                    # m, plate frame
    y: float = 0.0
    vx: float = 0.0                   # m/s
    vy: float = 0.0
    ball_found: bool = False          # fresh detection used this frame
    tracking_valid: bool = False      # fresh or coasting
    markers_found: int = 0
    pixel_u: float = -1.0             # raw detection (pixels), -1 when none
    pixel_v: float = -1.0
    plate_visible: bool = False
    # plate pose fitted in this frame: plate_center in the camera, X_C = R_CP X_P + t_CP
    # (None without markers), its covariance (6x6, [x y z rx ry rz], m^2 and rad^2, camera
    # axes) and the 1-sigma ball-position error it causes (m, math.inf: no usable pose)
    plate_pose: Optional[Tuple[np.ndarray, np.ndarray]] = None
    pose_covariance: Optional[np.ndarray] = None
    position_std_m: float = math.inf
    # the filter's constant disturbance as a plate-level offset per axis [rad] (the tilt that
    # holds the ball still), None unless it is estimated (disturbance_time_constant_s > 0)
    level_offset_rad: Optional[Tuple[float, float]] = None
    blob: Optional[BallBlob] = None
    measurement_m: Optional[Tuple[float, float]] = None
    timings_s: Dict[str, float] = field(default_factory=dict)


class BallTracker:
    """Stateful per-camera tracker. `process()` is called once per frame, in stamp order."""

    def __init__(self, config: Optional[TrackerConfig] = None, camera: Optional[CameraModel] = None,
                 undistort_mode: str = "points"):
        self.config = config or TrackerConfig.from_values()
        cfg = self.config
        self.plate = PlateLocator(cfg.geometry, cfg.startup_frames, cfg.startup_max_motion_px, cfg.plate_hold_s,
                                  cfg.marker_roi_margin, cfg.full_scan_period)
        self.segmenter = BallSegmenter(cfg.hsv_lower, cfg.hsv_upper, cfg.morph_kernel_px, cfg.min_circularity)
        self.kalman = BallKalman(KalmanConfig.from_tracker(cfg))
        self.undistort_mode = undistort_mode
        self.camera: Optional[CameraModel] = None
        self.undistorter: Optional[Undistorter] = None
        self.set_camera(camera)
        self.C_P: Optional[np.ndarray] = None           # camera centre, plate frame (for parallax)
        self._K_estimated: Optional[np.ndarray] = None
        self._K_nominal: Optional[np.ndarray] = None     # pose covariance without intrinsics
        self.plate_cmds = PlateCommandInput(cfg.rolling_factor * GRAVITY_M_S2, cfg.plate_cmd_delay_s,
                                            cfg.plate_cmd_timeout_s, lever_m=cfg.tilt_lever_m)
        # the delay the plate's measured tilt shows (None: plate_cmd_delay_s as configured)
        self.plate_cmd_delay = CommandDelayFromTilt.from_config(cfg, self.plate_cmds) \
            if cfg.estimate_plate_cmd_delay and cfg.use_plate_cmd else None
        self.frames = 0
        self.rejected_off_plate = 0
        self._last_ball_px: Optional[Tuple[float, float]] = None   # last frame's blob centre (u, v)
        self.ball_window_fallbacks = 0    # ball not wholly inside its window: the plate searched

    # -- inputs besides frames --------------------------------------------------------------------
    def set_camera(self, camera: Optional[CameraModel]) -> None:
        """Intrinsics/distortion (None: uncalibrated). Resets the camera-centre estimate."""
        self.camera = camera
        self.undistorter = Undistorter(camera, self.undistort_mode) if camera is not None else None
        self.C_P = None

    def set_plate_cmd(self, u_x: float, u_y: float, received_s: float) -> None:
        """Commanded tilts (rad) from /plate_cmd, used as known acceleration when enabled.
        `received_s` is on the same clock as `process(..., now_s)` (the node's receipt clock)."""
        self.plate_cmds.add(u_x, u_y, received_s)

    def known_acceleration(self, now_s: float) -> Optional[Tuple[float, float]]:
        """x'' = -k g sin(u_x), y'' = -k g sin(u_y) of the command in force `plate_cmd_delay_s`
        (or its estimate) before now_s, from a recent enough command stream, else None."""
        return self.known_inputs(now_s)[0]

    def known_inputs(self, now_s: float):
        """(known acceleration, the tilt's lever offset) at now_s (PlateCommandInput.inputs), or
        (None, None) without a recent command or with use_plate_cmd off."""
        if not self.config.use_plate_cmd:
            return None, None
        return self.plate_cmds.inputs(now_s)

    # -- the pipeline ----------------------------------------------------------------------------
    def process(self, image_bgr: np.ndarray, stamp_s: float, now_s: Optional[float] = None) -> TrackerResult:
        """Track the ball in one frame captured at `stamp_s` (seconds, any epoch). `now_s`:
        the clock /plate_cmd receipt times are on (default: the frame stamp)."""
        clock = time.perf_counter
        t0 = clock()
        self.frames += 1
        result = TrackerResult(stamp_s)
        timings = result.timings_s
        if self.undistorter is not None and self.undistort_mode == "image":
            image_bgr = self.undistorter.image(image_bgr)
        t1 = clock()
        timings["undistort"] = t1 - t0

        markers = self.plate.find_markers(image_bgr)   # grey only where it searches
        if self.undistorter is not None and markers:
            markers = {m: self.undistorter.points(c) for m, c in markers.items()}
        t2 = clock()
        timings["markers"] = t2 - t1

        result.markers_found = len(markers)
        if self.plate.update(markers, stamp_s):
            self._update_camera_centre(image_bgr.shape)
        result.plate_visible = self.plate.plate_visible(stamp_s)
        if markers and self.plate.H_IP is not None:
            self._pose_quality(result, image_bgr.shape)
        t3 = clock()
        timings["homography"] = t3 - t2

        z = None
        if result.plate_visible:
            z = self._measure_ball(image_bgr, result)
        else:
            self._last_ball_px = None
        t4 = clock()
        timings["ball"] = t4 - t3

        cmd_s = stamp_s if now_s is None else now_s
        if self.plate_cmd_delay is not None and result.plate_pose is not None:
            self.plate_cmd_delay.add_rotation(cmd_s, result.plate_pose[0])
        accel, lever = self.known_inputs(cmd_s)
        estimate = self.kalman.step(stamp_s, z, accel, lever)
        result.x, result.y, result.vx, result.vy = estimate.x, estimate.y, estimate.vx, estimate.vy
        result.ball_found, result.tracking_valid = estimate.fresh, estimate.valid
        if self.kalman.disturbance_state:
            result.level_offset_rad = self.kalman.level_offset_rad(self.plate_cmds.k_g)
        t5 = clock()
        timings["filter"] = t5 - t4
        timings["total"] = t5 - t0
        return result

    def _measure_ball(self, image_bgr: np.ndarray, result: TrackerResult) -> Optional[Tuple[float, float]]:
        cfg, plate = self.config, self.plate
        px_per_m = plate.px_per_m()
        r_min, r_max = cfg.ball_radius_range_m
        plate_window = plate.plate_window(image_bgr.shape, cfg.plate_margin_m)
        radius_range_px = (r_min * px_per_m, r_max * px_per_m)
        blob = self._find_ball_near_last(image_bgr, plate_window, radius_range_px)
        if blob is None:
            blob = self.segmenter.find(image_bgr, plate_window, radius_range_px)
        self._last_ball_px = (blob.u, blob.v) if blob is not None else None
        if blob is None:
            return None
        result.blob = blob
        result.pixel_u, result.pixel_v = blob.u, blob.v
        uv = np.array([[blob.u, blob.v]])
        if self.undistorter is not None:
            uv = self.undistorter.points(uv)
        x, y = self.pixel_to_plate(uv[0])
        if not plate.geometry.on_plate(x, y, cfg.plate_margin_m):
            self.rejected_off_plate += 1
            return None
        result.measurement_m = (x, y)
        return (x, y)

    def _find_ball_near_last(self, image_bgr: np.ndarray, plate_window, radius_range_px) -> Optional[BallBlob]:
        """The ball in a window around where the last frame found it (same colour test, a
        fraction of the pixels), or None when there was none, or the blob found is not wholly
        inside the window (it moved farther, or is cut by the window's edge): the caller
        searches the whole plate then."""
        if self._last_ball_px is None:
            return None
        u, v = self._last_ball_px
        half = BALL_WINDOW_RADII * radius_range_px[1]
        px0, py0, px1, py1 = plate_window
        window = (max(int(u - half), px0), max(int(v - half), py0),
                  min(int(u + half) + 1, px1), min(int(v + half) + 1, py1))
        if window == tuple(plate_window):
            return None
        blob = self.segmenter.find(image_bgr, window, radius_range_px)
        # a blob within the opening kernel of an inner window edge may be cut by it
        edge = max(self.config.morph_kernel_px, 1) + 1
        if blob is None or not all(
                inner == outer or abs(b - inner) >= edge
                for b, inner, outer in zip(blob.bbox_px, window, plate_window)):
            self.ball_window_fallbacks += 1
            return None
        return blob

    def pixel_to_plate(self, uv: np.ndarray) -> Tuple[float, float]:
        """Undistorted pixel of the ball centre -> plate (x, y) of the ball centre (m)."""
        p = apply_homography(self.plate.H_PI, uv)[0]       # ray hits the plate plane z = 0 here
        C = self.C_P
        if C is None or C[2] <= self.config.ball_radius_m:
            return float(p[0]), float(p[1])
        # the ray C -> p crosses z = r at C + (C_z - r) / C_z (p - C)
        s = (C[2] - self.config.ball_radius_m) / C[2]
        return float(C[0] + s * (p[0] - C[0])), float(C[1] + s * (p[1] - C[1]))

    def _update_camera_centre(self, shape) -> None:
        K = self.camera.K if self.camera is not None else self._estimate_K(shape)
        if K is not self.plate.K:
            self.plate.set_intrinsics(K)
        if K is not None and self.config.parallax_correction:
            R_CP, t_CP = self.plate.pose(K)
            self.C_P = -R_CP.T @ t_CP          # camera centre, plate frame (X_C = 0)

    def _pose_quality(self, result: TrackerResult, shape) -> None:
        """This frame's plate pose, its covariance and position_std_m (see pose_quality)."""
        plate, markers = self.plate, self.plate.markers
        K = plate.K
        if K is None:
            height, width = shape[:2]
            if self._K_nominal is None or self._K_nominal[0, 2] != (width - 1) / 2.0:
                f = NOMINAL_FOCAL_PER_WIDTH * width
                self._K_nominal = np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0, 0, 1.0]])
            K = self._K_nominal
        ids = sorted(markers)
        plate_pts = np.concatenate([plate.marker_corners_P[m] for m in ids])
        sigma_px = self.config.corner_noise_px
        if len(ids) >= FULL_FIT_MIN_MARKERS:
            # corner noise from the fit's residual when it says more (8 parameters at most)
            image_pts = np.concatenate([markers[m] for m in ids])
            residual = image_pts - apply_homography(plate.H_IP, plate_pts)
            sigma_px = max(sigma_px, float(np.sqrt(np.sum(residual ** 2) / (residual.size - 8))))
        # the pivot fit's prior is information too; a shift-only fit (no intrinsics) is
        # approximated by the same model (it is worse after a tilt: the figure is optimistic)
        prior = PRIOR_INFORMATION if plate.fit_kind != "homography" else None
        R_CP, t_CP = plate.pose(K)
        result.plate_pose = (R_CP, t_CP)
        result.pose_covariance = pose_covariance(plate_pts, K, R_CP, t_CP, sigma_px, prior)
        result.position_std_m = ball_position_std_m(result.pose_covariance)

    def _estimate_K(self, shape) -> Optional[np.ndarray]:
        """Intrinsics guessed from the start-up plate view (principal point at the image centre)."""
        if self._K_estimated is None and self.plate.H_full is not None:
            height, width = shape[:2]
            centre = ((width - 1) / 2.0, (height - 1) / 2.0)
            f = estimate_focal_px(self.plate.H_full, centre)
            if f is not None:
                self._K_estimated = np.array([[f, 0.0, centre[0]], [0.0, f, centre[1]], [0.0, 0.0, 1.0]])
        return self._K_estimated
