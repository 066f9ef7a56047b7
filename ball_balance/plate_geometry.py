"""The plate, its ArUco markers and the ball: the one source of these numbers (docs/design.md section 5).

Plate frame `plate_center`: origin at the plate's geometric centre, z along the normal,
x to the right and y up as seen by the overhead camera. Lengths in metres, mass in kg.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, Tuple

PLATE_FRAME = "plate_center"
PLATE_SIDE_M = 0.457
PLATE_THICKNESS_M = 0.006
# plate_center sits this far along tool0 z (10 mm standoff + half the thickness); the URDF
# (config/ur5e_ball_balance.urdf, joint tool0-plate_center) carries the same number.
PLATE_MOUNT_OFFSET_M = 0.013
PLATE_MASS_KG = 1.0            # 6 mm acrylic
# where a reference may take the ball's centre: |x|, |y| within this, the ball (BALL_RADIUS_M)
# then stays 8 mm inside the plate's edge
USABLE_HALF_WIDTH_M = 0.2

ARUCO_DICTIONARY = "DICT_4X4_50"
MARKER_SIDE_M = 0.040          # black border included
MARKER_OFFSET_M = 0.1835       # |x| = |y| of each marker centre
# marker id -> centre (x, y) in the plate frame; markers are axis-aligned, "up" = +y
MARKER_CENTRES_M: Dict[int, Tuple[float, float]] = {
    0: (-MARKER_OFFSET_M, -MARKER_OFFSET_M),
    1: (+MARKER_OFFSET_M, -MARKER_OFFSET_M),
    2: (-MARKER_OFFSET_M, +MARKER_OFFSET_M),
    3: (+MARKER_OFFSET_M, +MARKER_OFFSET_M),
}

BALL_RADIUS_M = 0.020          # 40 mm table-tennis ball
BALL_MASS_KG = 0.0027
# Rolling without slipping: x'' = k g sin(tilt), k = 1 / (1 + I / (m r^2)).
ROLLING_FACTOR_SHELL = 3.0 / 5.0   # thin shell, I = 2/3 m r^2
ROLLING_FACTOR_SOLID = 5.0 / 7.0   # solid ball, I = 2/5 m r^2

GRAVITY_M_S2 = 9.81


@dataclass(frozen=True)
class PlateGeometry:
    """Plate and marker layout, overridable by parameters (defaults: docs/design.md section 5)."""

    side_m: float = PLATE_SIDE_M
    marker_side_m: float = MARKER_SIDE_M
    marker_centres_m: Tuple[Tuple[int, float, float], ...] = tuple(
        (marker_id, x, y) for marker_id, (x, y) in MARKER_CENTRES_M.items())

    def marker_corners_m(self, marker_id: int) -> Tuple[Tuple[float, float], ...]:
        """Corners of one marker in the plate frame, in OpenCV's ArUco order:
        top-left, top-right, bottom-right, bottom-left as seen from the camera (y up)."""
        centre = {m: (x, y) for m, x, y in self.marker_centres_m}[marker_id]
        h = self.marker_side_m / 2.0
        cx, cy = centre
        return ((cx - h, cy + h), (cx + h, cy + h), (cx + h, cy - h), (cx - h, cy - h))

    def on_plate(self, x_m: float, y_m: float, margin_m: float = 0.0) -> bool:
        """True when (x, y) lies on the plate, widened by `margin_m`."""
        half = self.side_m / 2.0 + margin_m
        return abs(x_m) <= half and abs(y_m) <= half
