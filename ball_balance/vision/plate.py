"""The plate in the image: ArUco markers -> homography between plate metres and image pixels.

Symbols: H_IP maps plate-frame points (x, y, 1) in metres to image pixels (u, v, 1);
H_PI = inv(H_IP). Plate frame `plate_center` (docs/design.md section 5): x right, y up as seen
by the overhead camera, z along the normal toward the camera.

Life of a `PlateLocator`:
- start-up: full-image marker search; once all markers are seen for `startup_frames`
  frames without moving, their averaged corners give the reference fit H_full (locked);
- locked: markers are searched in small windows around their predicted positions, with
  one adaptive-threshold pass, all of OpenCV's where it missed (a full-image search every
  `full_scan_period` frames while one is missing); all markers
  refit H_full as a homography; with some hidden (a hand or the arm over them) and
  intrinsics known, the plate pose is fitted with a prior that the plate pivots about its
  centre (`fit_pose_with_pivot_prior`; 6 pose parameters instead of 8 homography ones: with
  3 markers the far corner is 5x more exact than a homography's); without intrinsics >= 3
  markers refit the homography, 1-2 shift H_full by their mean image displacement; with
  none, the last H_IP is kept for `plate_hold_s`, then the plate counts as not visible.
  `fit_kind` says which fit made the current H_IP.
"""
from __future__ import annotations

from typing import Dict, List, Optional, Tuple

import cv2
import numpy as np

from ball_balance.plate_geometry import PlateGeometry

FULL_FIT_MIN_MARKERS = 3   # fewer visible markers: pose fit with a pivot prior, or a shift
# the pivot prior of the 1-2 marker fit (1 sigma): the plate centre stays within a few mm of
# where the last full fit saw it, the tilt may have changed by tenths of a radian
PIVOT_PRIOR_SIGMA_T_M = 0.005
PIVOT_PRIOR_SIGMA_ROT_RAD = 0.3
STARTUP_PATIENCE = 3       # x startup_frames frames of a moving plate: lock on the latest frame

Window = Tuple[int, int, int, int]   # x0, y0, x1, y1 (pixels, end exclusive)


# in a window around a predicted marker one adaptive-threshold pass (block size in px, the
# largest of OpenCV's default 3/13/23: on rendered frames its corners give the same plate
# fit as all three) finds it; the three passes cost 2x as much and run only where that one
# pass missed its marker
WINDOW_THRESHOLD_BLOCK_PX = 23


class MarkerDetector:
    """DICT_4X4_50 detection with sub-pixel corners, on the whole image or in windows."""

    def __init__(self):
        dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
        self._detector = cv2.aruco.ArucoDetector(dictionary, _detector_parameters())
        single = _detector_parameters()
        single.adaptiveThreshWinSizeMin = single.adaptiveThreshWinSizeMax = WINDOW_THRESHOLD_BLOCK_PX
        self._window_detector = cv2.aruco.ArucoDetector(dictionary, single)
        self.window_fallbacks = 0   # windows where the single pass missed and all passes ran

    def detect(self, image: np.ndarray) -> Dict[int, np.ndarray]:
        """Markers in the whole image (grey, or BGR converted here): id -> corners (4, 2)
        float64 pixels, OpenCV order."""
        return self._detect(self._detector, image)

    @staticmethod
    def _detect(detector, image: np.ndarray) -> Dict[int, np.ndarray]:
        corners, ids, _ = detector.detectMarkers(_gray(image))
        found: Dict[int, np.ndarray] = {}
        if ids is not None:
            for marker_id, c in zip(ids.ravel(), corners):
                found.setdefault(int(marker_id), c.reshape(4, 2).astype(np.float64))
        return found

    def detect_in_windows(self, image: np.ndarray, windows: Dict[int, Window]) -> Dict[int, np.ndarray]:
        """Look for each expected marker id only inside its window (a BGR image is converted
        to grey window by window: a few percent of the frame instead of all of it). One
        threshold pass first, all of them where it missed the marker."""
        found: Dict[int, np.ndarray] = {}
        for marker_id, (x0, y0, x1, y1) in windows.items():
            if x1 - x0 < 8 or y1 - y0 < 8:
                continue
            grey = _gray(image[y0:y1, x0:x1])
            corners = self._detect(self._window_detector, grey).get(marker_id)
            if corners is None:
                self.window_fallbacks += 1
                corners = self._detect(self._detector, grey).get(marker_id)
            if corners is not None:
                found[marker_id] = corners + (x0, y0)
        return found


def _detector_parameters():
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    params.cornerRefinementWinSize = 3
    return params


def _gray(image: np.ndarray) -> np.ndarray:
    return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


def apply_homography(H: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Map (n, 2) points through the 3x3 homography H."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    q = p @ H[:, :2].T + H[:, 2]
    return q[:, :2] / q[:, 2:3]


def estimate_focal_px(H_IP: np.ndarray, principal_point: Tuple[float, float]) -> Optional[float]:
    """Focal length from a plane homography (square pixels, known principal point), or None
    when the view is too close to fronto-parallel for the plate to reveal it."""
    T = np.array([[1.0, 0.0, -principal_point[0]], [0.0, 1.0, -principal_point[1]], [0.0, 0.0, 1.0]])
    h = T @ H_IP
    h = h / np.linalg.norm(h[:, :2])
    (a1, a2), (b1, b2), (c1, c2) = h[0, :2], h[1, :2], h[2, :2]
    # r1 . r2 = 0 and |r1| = |r2| with K = diag(f, f, 1) give two estimates of f^2
    estimates = []
    if abs(c1 * c2) > 1e-9:
        estimates.append(-(a1 * a2 + b1 * b2) / (c1 * c2))
    if abs(c1 * c1 - c2 * c2) > 1e-9:
        estimates.append(-(a1 * a1 + b1 * b1 - a2 * a2 - b2 * b2) / (c1 * c1 - c2 * c2))
    good = [f2 for f2 in estimates if f2 > 0.0]
    if not good:
        return None
    f = float(np.sqrt(np.median(good)))
    # a nearly fronto-parallel view makes the estimate explode: accept only plausible values
    return f if 0.2 * np.linalg.norm(principal_point) < f < 20.0 * np.linalg.norm(principal_point) else None


def plate_pose(H_IP: np.ndarray, K: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Plate pose in the camera, (R_CP, t_CP), from H_IP = K [r1 r2 t] (up to scale):
    X_C = R_CP X_P + t_CP."""
    M = np.linalg.solve(K, H_IP)
    scale = 0.5 * (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    r1, r2, t = M[:, 0] / scale, M[:, 1] / scale, M[:, 2] / scale
    if t[2] < 0.0:          # the plate is in front of the camera: t_z > 0
        r1, r2, t = -r1, -r2, -t
    r3 = (r1[1] * r2[2] - r1[2] * r2[1], r1[2] * r2[0] - r1[0] * r2[2], r1[0] * r2[1] - r1[1] * r2[0])
    U, _, Vt = np.linalg.svd(np.column_stack([r1, r2, r3]))    # nearest rotation
    return U @ Vt, t


def camera_centre_in_plate(H_IP: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Camera centre C_P (3,) in the plate frame: X_C = 0  =>  C_P = -R_CP^T t_CP."""
    R_CP, t_CP = plate_pose(H_IP, K)
    return -R_CP.T @ t_CP


def fit_pose_with_pivot_prior(plate_pts: np.ndarray, image_pts: np.ndarray, K: np.ndarray, R_ref: np.ndarray,
                              t_ref: np.ndarray, sigma_px: float = 0.5, sigma_t_m: float = PIVOT_PRIOR_SIGMA_T_M,
                              sigma_rot_rad: float = PIVOT_PRIOR_SIGMA_ROT_RAD, iterations: int = 5) -> np.ndarray:
    """H_IP from a few marker corners, for a plate that tilts about its centre.

    Gauss-Newton on x = (rotation vector, t_CP) minimising
    |image residual|^2 / sigma_px^2 + |t - t_ref|^2 / sigma_t^2 + |rvec - rvec_ref|^2 / sigma_rot^2:
    the centre stays near where the last full fit saw it (the arm pivots the plate about
    it), the tilt follows the visible corners. 1-2 markers cannot reveal the tilt on their
    own (it shows only as perspective), this prior makes it observable.
    """
    rvec_ref = cv2.Rodrigues(R_ref)[0].ravel()
    x_ref = np.concatenate([rvec_ref, t_ref])
    x = x_ref.copy()
    points = np.column_stack([plate_pts, np.zeros(len(plate_pts))])
    Lambda = np.diag([sigma_rot_rad ** -2] * 3 + [sigma_t_m ** -2] * 3)     # prior information
    w = sigma_px ** -2
    for _ in range(iterations):
        projected, J = cv2.projectPoints(points, x[:3], x[3:], K, None)
        r = (image_pts - projected.reshape(-1, 2)).ravel()                   # residual (px)
        J = J[:, :6]                                                          # d proj / d (rvec, t)
        x = x + np.linalg.solve(w * J.T @ J + Lambda, w * J.T @ r - Lambda @ (x - x_ref))
    R = cv2.Rodrigues(x[:3])[0]
    H = K @ np.column_stack([R[:, 0], R[:, 1], x[3:]])
    return H / H[2, 2]


class PlateLocator:
    """Marker search and the plate homography over a stream of frames (see module docstring)."""

    def __init__(self, geometry: PlateGeometry, startup_frames: int = 10, startup_max_motion_px: float = 2.0,
                 plate_hold_s: float = 0.5, marker_roi_margin: float = 1.0, full_scan_period: int = 10):
        self.geometry = geometry
        self.startup_frames = startup_frames
        self.startup_max_motion_px = startup_max_motion_px
        self.plate_hold_s = plate_hold_s
        self.marker_roi_margin = marker_roi_margin
        self.full_scan_period = full_scan_period
        self.marker_ids: List[int] = [m for m, _, _ in geometry.marker_centres_m]
        # marker id -> its corners (4, 2) in plate metres, OpenCV corner order
        self.marker_corners_P = {m: np.array(geometry.marker_corners_m(m)) for m in self.marker_ids}
        self._all_corners_P = np.concatenate([self.marker_corners_P[m] for m in self.marker_ids])
        self.detector = MarkerDetector()
        self.H_full: Optional[np.ndarray] = None   # reference fit (start-up average or >= 3 markers)
        self.K: Optional[np.ndarray] = None        # intrinsics, when known: 1-2 marker pose fit
        self._pose_ref: Optional[Tuple[np.ndarray, np.ndarray]] = None   # (R_CP, t_CP) of H_full
        self._pose_cache: Optional[tuple] = None   # (H_IP, K, (R_CP, t_CP)): pose() once per fit
        self.H_IP: Optional[np.ndarray] = None     # current plate -> image
        self.H_PI: Optional[np.ndarray] = None     # current image -> plate
        self.last_seen_s: Optional[float] = None   # stamp of the last frame with a marker
        self.markers: Dict[int, np.ndarray] = {}   # this frame's markers (image px)
        self.fit_kind = ""                         # "homography", "pivot" or "shift": what made H_IP
        self._startup_sum: Optional[np.ndarray] = None   # corners summed over the steady window
        self._startup_count = 0                          # frames in that sum
        self._startup_seen = 0                           # frames with all markers before the lock
        self._frames_since_full_scan = 0

    @property
    def locked(self) -> bool:
        """The start-up plate pose has been established."""
        return self.H_full is not None

    def plate_visible(self, stamp_s: float) -> bool:
        """A plate pose usable at `stamp_s` (markers seen recently enough)."""
        return self.H_IP is not None and self.last_seen_s is not None and \
            stamp_s - self.last_seen_s <= self.plate_hold_s

    # -- marker search -----------------------------------------------------------------------
    def find_markers(self, image: np.ndarray) -> Dict[int, np.ndarray]:
        """This frame's known markers: windows around predictions once locked, else full image.
        `image`: grey, or BGR (then only what is searched is converted to grey)."""
        if self.H_IP is None:
            found = self.detector.detect(image)
        else:
            found = self.detector.detect_in_windows(image, self._windows(image.shape))
            self._frames_since_full_scan += 1
            # none in their windows (the plate jumped, or all covered): look everywhere now;
            # some missing (covered by a hand or the ball): look everywhere now and then
            if not found or (len(found) < len(self.marker_ids)
                             and self._frames_since_full_scan >= self.full_scan_period):
                self._frames_since_full_scan = 0
                full = self.detector.detect(image)
                if len(full) > len(found):
                    found = full
        return {m: c for m, c in found.items() if m in self.marker_corners_P}

    def _windows(self, shape) -> Dict[int, Window]:
        height, width = shape[:2]
        # all markers' corners through H_IP at once: (markers, 4, 2)
        corners_I = apply_homography(self.H_IP, self._all_corners_P).reshape(len(self.marker_ids), 4, 2)
        low, high = corners_I.min(axis=1), corners_I.max(axis=1)
        pad = (high - low).max(axis=1, keepdims=True) * self.marker_roi_margin   # marker sides
        low = np.floor(low - pad).astype(int).tolist()
        high = np.ceil(high + pad).astype(int).tolist()
        return {m: (max(x0, 0), max(y0, 0), min(x1, width), min(y1, height))
                for m, (x0, y0), (x1, y1) in zip(self.marker_ids, low, high)}

    # -- homography ------------------------------------------------------------------------
    def update(self, markers: Dict[int, np.ndarray], stamp_s: float) -> bool:
        """Fold this frame's markers into the plate pose; True when H_IP changed."""
        self.markers = markers
        if not markers:
            return False
        self.last_seen_s = stamp_s
        if not self.locked:
            self._startup(markers)
            return self.locked
        ids = sorted(markers)
        image_pts = np.concatenate([markers[m] for m in ids])
        plate_pts = np.concatenate([self.marker_corners_P[m] for m in ids])
        if len(ids) == len(self.marker_ids) or (len(ids) >= FULL_FIT_MIN_MARKERS and self._pose_ref is None):
            self._set(self.fit(plate_pts, image_pts), full=True)
            self.fit_kind = "homography"
        elif self._pose_ref is not None:
            H_IP = fit_pose_with_pivot_prior(plate_pts, image_pts, self.K, *self._pose_ref)
            self._set(H_IP, full=len(ids) >= FULL_FIT_MIN_MARKERS)
            self.fit_kind = "pivot"
        else:
            # without intrinsics: a tilt shows as a perspective change that 1-2 corner markers
            # cannot reveal (a similarity fitted on them extrapolates worse than none): shift
            du, dv = (image_pts - apply_homography(self.H_full, plate_pts)).mean(axis=0)
            self._set(np.array([[1.0, 0.0, du], [0.0, 1.0, dv], [0.0, 0.0, 1.0]]) @ self.H_full, full=False)
            self.fit_kind = "shift"
        return True

    def _startup(self, markers: Dict[int, np.ndarray]) -> None:
        """Average all markers' corners over `startup_frames` steady frames, then lock. A plate
        that keeps moving (more than STARTUP_PATIENCE x startup_frames frames with all markers
        but never steady) is locked on the latest frame instead of never."""
        if len(markers) < len(self.marker_ids):
            self._startup_sum, self._startup_count = None, 0
            return
        corners = np.stack([markers[m] for m in self.marker_ids])
        self._startup_seen += 1
        if self._startup_count:
            mean = self._startup_sum / self._startup_count
            if np.max(np.linalg.norm(corners - mean, axis=-1)) > self.startup_max_motion_px:
                self._startup_sum, self._startup_count = None, 0     # moved: start again
        self._startup_sum = corners if self._startup_sum is None else self._startup_sum + corners
        self._startup_count += 1
        if self._startup_count >= self.startup_frames or self._startup_seen >= STARTUP_PATIENCE * self.startup_frames:
            mean = (self._startup_sum / self._startup_count).reshape(-1, 2)
            plate_pts = np.concatenate([self.marker_corners_P[m] for m in self.marker_ids])
            self._set(self.fit(plate_pts, mean), full=True)
            self.fit_kind = "homography"

    @staticmethod
    def fit(plate_pts: np.ndarray, image_pts: np.ndarray) -> np.ndarray:
        """Least-squares homography H_IP from plate metres to image pixels."""
        H, _ = cv2.findHomography(plate_pts.astype(np.float64), image_pts.astype(np.float64), 0)
        if H is None:
            raise np.linalg.LinAlgError("degenerate marker corners")
        return H

    def set_intrinsics(self, K: Optional[np.ndarray]) -> None:
        """Intrinsics of the (undistorted) corner pixels, or None: enables the 1-2 marker pose fit."""
        self.K = K
        self._pose_ref = plate_pose(self.H_full, K) if (K is not None and self.H_full is not None) else None

    def _set(self, H_IP: np.ndarray, full: bool) -> None:
        self.H_IP = H_IP
        self.H_PI = np.linalg.inv(H_IP)
        if full:
            self.H_full = H_IP
            self._pose_ref = self.pose(self.K) if self.K is not None else None

    def pose(self, K: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """(R_CP, t_CP) of the current H_IP with intrinsics K, computed once per fit."""
        cache = self._pose_cache
        if cache is None or cache[0] is not self.H_IP or cache[1] is not K:
            cache = self._pose_cache = (self.H_IP, K, plate_pose(self.H_IP, K))
        return cache[2]

    def reset(self) -> None:
        """Forget the plate pose (back to start-up)."""
        self.H_full = self.H_IP = self.H_PI = self.last_seen_s = self._pose_ref = None
        self.fit_kind = ""
        self._startup_sum, self._startup_count, self._startup_seen = None, 0, 0

    # -- helpers for the ball search -------------------------------------------------------
    def plate_window(self, shape, margin_m: float) -> Window:
        """Bounding box in the image of the plate widened by `margin_m`, clipped to the image."""
        half = self.geometry.side_m / 2.0 + margin_m
        corners_I = apply_homography(self.H_IP, np.array([[-half, -half], [half, -half], [half, half],
                                                          [-half, half]]))
        height, width = shape[:2]
        x0, y0 = np.floor(corners_I.min(axis=0)).astype(int)
        x1, y1 = np.ceil(corners_I.max(axis=0)).astype(int) + 1
        return max(x0, 0), max(y0, 0), min(x1, width), min(y1, height)

    def px_per_m(self, x_m: float = 0.0, y_m: float = 0.0) -> float:
        """Local image scale of the plate at (x, y): sqrt of the homography's Jacobian."""
        H = self.H_IP
        w = H[2, 0] * x_m + H[2, 1] * y_m + H[2, 2]
        u = (H[0, 0] * x_m + H[0, 1] * y_m + H[0, 2]) / w
        v = (H[1, 0] * x_m + H[1, 1] * y_m + H[1, 2]) / w
        J = np.array([[H[0, 0] - u * H[2, 0], H[0, 1] - u * H[2, 1]],
                      [H[1, 0] - v * H[2, 0], H[1, 1] - v * H[2, 1]]]) / w
        return float(np.sqrt(abs(np.linalg.det(J))))
