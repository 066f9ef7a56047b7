"""Parameters of the ball tracker: one schema (defaults, units, bounds), one frozen config.

`TRACKER_SCHEMA` holds the algorithm's parameters, `SOURCE_SCHEMA` where frames come from.
The node declares both (plus its own topic parameters); tools and tests build a
`TrackerConfig` from a plain dict with `TrackerConfig.from_values`. Plate and ball
defaults come from `ball_balance.plate_geometry` (the one source).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Optional, Tuple

from ball_balance import plate_geometry as pg
from controller_manager_py.parameters import Param, validate


def _three_ints_0_255(value) -> Optional[str]:
    if len(value) != 3 or not all(isinstance(v, int) and 0 <= v <= 255 for v in value):
        return "must be 3 integers in 0..255 (H in 0..179, S, V)"
    return None


def _range_pair(value) -> Optional[str]:
    if len(value) != 2 or not 0.0 < value[0] < value[1]:
        return "must be [min, max] with 0 < min < max"
    return None


_IDS = tuple(pg.MARKER_CENTRES_M)
SOURCE_SCHEMA = (
    Param("source", "topic", "where frames come from", choices=("topic", "camera", "file"), user_facing=True),
    Param("image_topic", "/camera/image_raw", "sensor_msgs/Image input (source=topic), bgr8 or rgb8", user_facing=True),
    Param("camera_info_topic", "/camera/camera_info",
          "sensor_msgs/CameraInfo for intrinsics when no calibration_file ('' = off)", user_facing=True),
    Param("camera_device", "0", "USB camera: device index ('0') or path ('/dev/video0') (source=camera)",
          user_facing=True),
    Param("camera_width", 640, "requested capture width (source=camera)", "px", 16, 8192, user_facing=True),
    Param("camera_height", 480, "requested capture height (source=camera)", "px", 16, 8192, user_facing=True),
    Param("camera_fps", 30.0, "requested capture rate (source=camera)", "Hz", 1.0, 1000.0, user_facing=True),
    Param("video_file", "", "video file to replay (source=file)", user_facing=True),
    Param("video_loop", False, "restart the video file at its end (source=file)"),
    Param("video_rate_hz", 0.0, "replay rate (source=file); 0 = the file's own rate", "Hz", 0.0, 1000.0),
    Param("calibration_file", "", "camera calibration YAML (ROS camera_info format); '' = none", user_facing=True),
    Param("undistort", "points", "with a calibration: undistort detected points (cheap) or whole images",
          choices=("points", "image")),
)

TRACKER_SCHEMA = (
    # plate and markers (docs/design.md section 5)
    Param("plate_side_m", pg.PLATE_SIDE_M, "plate side length", "m", 0.05, 5.0, user_facing=True),
    Param("marker_side_m", pg.MARKER_SIDE_M, "ArUco marker side, black border included", "m", 0.005, 1.0,
          user_facing=True),
    Param("marker_ids", _IDS, "ArUco DICT_4X4_50 ids on the plate",
          check=lambda v: None if len(v) >= 1 and all(isinstance(i, int) and 0 <= i < 50 for i in v)
          else "must be ids in 0..49", user_facing=True),
    Param("marker_x_m", tuple(pg.MARKER_CENTRES_M[i][0] for i in _IDS), "marker centres x (plate frame)", "m"),
    Param("marker_y_m", tuple(pg.MARKER_CENTRES_M[i][1] for i in _IDS), "marker centres y (plate frame)", "m"),
    Param("startup_frames", 10, "frames with all markers visible averaged into the start-up plate pose",
          "frames", 1, 1000),
    Param("startup_max_motion_px", 2.0, "start-up averaging restarts if a corner moves more than this",
          "px", 0.1, 100.0),
    Param("plate_hold_s", 0.5, "keep the last plate pose this long when no marker is visible", "s", 0.0, 60.0),
    Param("marker_roi_margin", 1.0, "search window around each predicted marker, in marker sides",
          "", 0.2, 10.0),
    Param("full_scan_period", 10, "while a marker is missing, search the whole image every N frames",
          "frames", 1, 10000),
    Param("corner_noise_px", 0.3,
          "marker corner noise (1 sigma) for the plate pose covariance; the fit residual when larger",
          "px", 0.01, 10.0),
    Param("parallax_correction", True,
          "map the ball centre at its height above the plate (needs intrinsics, or estimates them)"),
    # ball segmentation
    Param("hsv_lower", (0, 100, 60), "lower HSV bound of the ball colour (OpenCV H 0..179)",
          check=_three_ints_0_255, user_facing=True),
    Param("hsv_upper", (25, 255, 255), "upper HSV bound of the ball colour", check=_three_ints_0_255, user_facing=True),
    Param("morph_kernel_px", 3, "morphological opening kernel size (0 = none)", "px", 0, 31),
    Param("min_circularity", 0.6, "minimum 4*pi*area/perimeter^2 of the ball blob", "", 0.0, 1.0),
    Param("ball_radius_m", pg.BALL_RADIUS_M, "ball radius", "m", 0.001, 0.5, user_facing=True),
    Param("ball_radius_range_m", (0.012, 0.030), "accepted apparent blob radius [min, max]", "m",
          check=_range_pair),
    Param("plate_margin_m", 0.010, "detections farther than this outside the plate are rejected", "m", 0.0, 1.0),
    # Kalman filter
    Param("meas_noise_m", 0.0010, "measurement noise (1 sigma) per axis", "m", 1e-6, 1.0),
    Param("accel_noise_m_s2", 1.0, "white-noise acceleration (1 sigma) of the process model", "m/s^2",
          1e-4, 1000.0),
    Param("init_vel_std_m_s", 0.5, "velocity uncertainty (1 sigma) at track start", "m/s", 1e-4, 100.0),
    Param("gate_sigma", 6.0, "reject detections farther than this Mahalanobis distance (during a push's hold, "
          "unless the constant-velocity filter takes them)", "", 1.0, 1000.0),
    Param("max_coast_frames", 5, "frames predicted without a detection before the track is reset",
          "frames", 0, 1000),
    Param("max_dt_s", 0.5, "a gap between frames longer than this resets the track", "s", 0.001, 60.0),
    Param("use_plate_cmd", True, "use the commanded tilt on /plate_cmd as known acceleration"),
    Param("plate_cmd_timeout_s", 0.2, "ignore the commanded tilts when the last is older than this", "s", 0.0, 10.0),
    Param("plate_cmd_delay_s", 0.0, "the plate reaches a commanded tilt this long after it is received "
          "(with estimate_plate_cmd_delay: the start value)", "s", 0.0, 1.0),
    Param("estimate_plate_cmd_delay", True,
          "measure that delay online: the plate's tilt from its marker pose, aligned with the commands' "
          "history (keeps the current value while the plate is still or its pose is lost)"),
    Param("plate_cmd_delay_max_s", 0.3, "longest delay the estimate considers", "s", 0.01, 1.0),
    Param("plate_cmd_delay_window_s", 3.0, "the estimate aligns the tilts and commands of this long a window",
          "s", 0.5, 30.0),
    Param("tilt_lever_m", pg.BALL_RADIUS_M + pg.ROLLING_FACTOR_SHELL * pg.PLATE_THICKNESS_M / 2.0,
          "the ball's plate-frame position moves this much per rad of plate tilt besides its rolling: "
          "ball radius + rolling factor x depth of the tilt axis below the plate's surface (the default: "
          "a shell on a plate tilting about its mid-plane); 0 = not modelled", "m", 0.0, 1.0),
    Param("cmd_accel_noise_m_s2", 0.05,
          "white-noise acceleration (1 sigma) of the process model while a commanded tilt is known "
          "(accel_noise_m_s2 without one)", "m/s^2", 1e-4, 1000.0),
    Param("disturbance_time_constant_s", 20.0,
          "the filter also estimates a constant acceleration of the ball besides the commanded tilt's "
          "(a plate off level, a force on the ball): a random walk over about this time constant between "
          "changes that a test on the innovations finds (docs/tracker.md), published as a plate-level "
          "offset on /ball_level_offset, which the controllers cancel (offset-free control); 0 = off", "s",
          0.0, 60.0),
    Param("estimate_input_gain", True,
          "estimate online the ratio of the ball's acceleration to the commanded tilt's -k g sin(u)"),
    Param("input_gain_bounds", (0.4, 2.5), "[min, max] of that ratio", "", check=_range_pair),
    Param("input_gain_std", 0.3, "uncertainty (1 sigma) of that ratio at the first track", "", 0.0, 10.0),
    Param("input_gain_rate_per_s", 0.05, "random-walk rate of that ratio (1 sigma per sqrt(s))",
          "1/sqrt(s)", 0.0, 10.0),
    Param("model_mismatch_time_constant_s", 0.3,
          "time constant of the running innovation consistency that raises cmd_accel_noise_m_s2 (up to "
          "accel_noise_m_s2) while the detections disagree with the model; 0 = off", "s", 0.0, 60.0,
          formerly=("consistency_time_s",)),
    Param("maneuver_sigma", 3.5,
          "a detection farther than this Mahalanobis distance re-predicts its frame with accel_noise_m_s2 "
          "(a push the commanded tilt does not explain); 0 = off", "", 0.0, 1000.0),
    Param("maneuver_hold_s", 1.0,
          "after such a detection (while the model had agreed with the detections), report for this long "
          "the velocity of a constant-velocity filter with accel_noise_m_s2 run alongside, which takes up "
          "a push within a frame or two, and predict with at least accel_noise_m_s2 (the push is motion the "
          "commanded tilt does not explain), so the position follows the pushed ball; 0 = off", "s", 0.0, 10.0),
    Param("maneuver_confirm_sigma", 1.5,
          "while the noise asks for a confirmation, a detection beyond maneuver_sigma makes a push only when the "
          "next one points the same way beyond this Mahalanobis distance (one beyond gate_sigma always does)",
          "", 0.0, 1000.0),
    Param("maneuver_confirm_noise_m", 0.002,
          "a push needs that confirmation while the measurement noise (1 sigma, estimated) is at least this; "
          "below it one detection beyond maneuver_sigma makes a push (1 m: never confirm)", "m", 0.0, 1.0),
    Param("adaptive_meas_noise", True,
          "estimate the measurement noise online from the detections' scatter, within "
          "[meas_noise_m, meas_noise_max_m]"),
    Param("meas_noise_max_m", 0.02, "upper bound of the estimated measurement noise (1 sigma per axis)",
          "m", 1e-6, 1.0),
    Param("meas_noise_window_frames", 60, "detections the measurement-noise estimate is taken over",
          "frames", 5, 100000),
    Param("rolling_factor", pg.ROLLING_FACTOR_SHELL, "x'' = -k g sin(u): 0.6 thin shell, 5/7 solid ball",
          "", 0.0, 1.0),
)


@dataclass(frozen=True)
class TrackerConfig:
    """Validated, immutable tracker parameters (see TRACKER_SCHEMA for meanings and units)."""

    plate_side_m: float
    marker_side_m: float
    marker_centres_m: Tuple[Tuple[int, float, float], ...]
    startup_frames: int
    startup_max_motion_px: float
    plate_hold_s: float
    marker_roi_margin: float
    full_scan_period: int
    corner_noise_px: float
    parallax_correction: bool
    hsv_lower: Tuple[int, int, int]
    hsv_upper: Tuple[int, int, int]
    morph_kernel_px: int
    min_circularity: float
    ball_radius_m: float
    ball_radius_range_m: Tuple[float, float]
    plate_margin_m: float
    meas_noise_m: float
    accel_noise_m_s2: float
    init_vel_std_m_s: float
    gate_sigma: float
    max_coast_frames: int
    max_dt_s: float
    use_plate_cmd: bool
    plate_cmd_timeout_s: float
    plate_cmd_delay_s: float
    estimate_plate_cmd_delay: bool
    plate_cmd_delay_max_s: float
    plate_cmd_delay_window_s: float
    tilt_lever_m: float
    cmd_accel_noise_m_s2: float
    disturbance_time_constant_s: float
    estimate_input_gain: bool
    input_gain_bounds: Tuple[float, float]
    input_gain_std: float
    input_gain_rate_per_s: float
    model_mismatch_time_constant_s: float
    maneuver_sigma: float
    maneuver_hold_s: float
    maneuver_confirm_sigma: float
    maneuver_confirm_noise_m: float
    adaptive_meas_noise: bool
    meas_noise_max_m: float
    meas_noise_window_frames: int
    rolling_factor: float

    @classmethod
    def from_values(cls, values: Optional[Mapping[str, Any]] = None) -> TrackerConfig:
        """Validate `values` (missing ones take the schema default); ParameterError if bad."""
        v = validate(TRACKER_SCHEMA, values, allow_unknown=True)
        ids, xs, ys = v["marker_ids"], v["marker_x_m"], v["marker_y_m"]
        if not len(ids) == len(xs) == len(ys):
            from controller_manager_py.parameters import ParameterError
            raise ParameterError("parameters 'marker_ids', 'marker_x_m', 'marker_y_m' must have the same length")
        fields = {k: v[k] for k in cls.__dataclass_fields__ if k in v}
        fields["marker_centres_m"] = tuple((int(i), float(x), float(y)) for i, x, y in zip(ids, xs, ys))
        fields["hsv_lower"] = tuple(int(c) for c in v["hsv_lower"])
        fields["hsv_upper"] = tuple(int(c) for c in v["hsv_upper"])
        return cls(**fields)

    @property
    def geometry(self) -> pg.PlateGeometry:
        return pg.PlateGeometry(side_m=self.plate_side_m, marker_side_m=self.marker_side_m,
                                marker_centres_m=self.marker_centres_m)
