"""References r(t) the ball tracks, in the plate frame [m] (docs/design.md section 6, step 3).

Every reference gives position, velocity and acceleration at time t [s] since it started,
so controllers can use velocity/acceleration feed-forward and preview (MPC). `make_reference`
builds one from the controller's parameters; `path_points` samples one period for display.
"""
from __future__ import annotations

import bisect
import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence, Tuple

import numpy as np

from ball_balance.plate_geometry import USABLE_HALF_WIDTH_M
from controller_manager_py.text_files import TextFileError, read_text_file

PATH_CHECK_POINTS = 721     # a parametric path checked at 0.5 degree steps of its period
CSV_MAX_BYTES = 50_000_000  # a path at 1 kHz for an hour is about 40 MB of rows
KINDS = ("stationary", "circle", "figure_eight", "square", "step", "csv")


class ReferenceError(ValueError):
    """A reference definition is unusable (bad parameter, bad CSV row)."""


@dataclass(frozen=True)
class RefSample:
    """Reference at one instant: position [m], velocity [m/s], acceleration [m/s^2], shape (2,)."""

    p: np.ndarray
    v: np.ndarray
    a: np.ndarray


class Reference:
    """Base: subclasses implement `sample(t_s)`; `period_s` is the repeat time (inf if none)."""

    period_s: float = math.inf

    def sample(self, t_s: float) -> RefSample:
        raise NotImplementedError

    def path_points(self, n: int = 100) -> np.ndarray:
        """Positions over one period (or the first 10 s), shape (n, 2), for visualisation."""
        span = self.period_s if math.isfinite(self.period_s) else 10.0
        return np.array([self.sample(span * i / (n - 1)).p for i in range(n)])


def _z():
    return np.zeros(2)


class Stationary(Reference):
    def __init__(self, centre=(0.0, 0.0)):
        self.centre = np.asarray(centre, dtype=float)

    def sample(self, t_s: float) -> RefSample:
        return RefSample(self.centre.copy(), _z(), _z())


class Circle(Reference):
    """Counter-clockwise circle of radius_m around centre, one turn per period_s."""

    def __init__(self, radius_m: float, period_s: float, centre=(0.0, 0.0)):
        _positive(radius_m=radius_m, period_s=period_s)
        self.radius_m, self.period_s, self.centre = radius_m, period_s, np.asarray(centre, dtype=float)

    def sample(self, t_s: float) -> RefSample:
        w = 2.0 * math.pi / self.period_s
        c, s = math.cos(w * t_s), math.sin(w * t_s)
        r = self.radius_m
        return RefSample(self.centre + r * np.array([c, s]), r * w * np.array([-s, c]),
                         -r * w * w * np.array([c, s]))


class FigureEight(Reference):
    """Lemniscate of Gerono: x = R sin(wt), y = (R/2) sin(2wt); width 2R, one loop per period."""

    def __init__(self, radius_m: float, period_s: float, centre=(0.0, 0.0)):
        _positive(radius_m=radius_m, period_s=period_s)
        self.radius_m, self.period_s, self.centre = radius_m, period_s, np.asarray(centre, dtype=float)

    def sample(self, t_s: float) -> RefSample:
        w = 2.0 * math.pi / self.period_s
        r = self.radius_m
        p = np.array([r * math.sin(w * t_s), 0.5 * r * math.sin(2 * w * t_s)])
        v = np.array([r * w * math.cos(w * t_s), r * w * math.cos(2 * w * t_s)])
        a = np.array([-r * w * w * math.sin(w * t_s), -2.0 * r * w * w * math.sin(2 * w * t_s)])
        return RefSample(self.centre + p, v, a)


# Smoothing of waypoint paths (Waypoints, hold=False).
# The acceleration a turn at a point may ask of the ball: a feed-forward tilt of 0.2 / (0.6 g) =
# 0.034 rad, under a quarter of the controllers' tilt limit (max_tilt_cmd_rad 0.15), which leaves
# the rest to the feedback; the benchmark's circle and figure-eight ask 0.04 and 0.055 m/s^2. The
# tracking error on a corner grows with it and the corner cut shrinks (the PID on the 0.15 m square
# in 8 s, 3 seeds: RMSE after 5 s 0.5 / 0.7 / 1.1 mm, tilt-rate RMS 0.10 / 0.12 / 0.20 rad/s,
# corners cut by 16 / 7.9 / 4.0 mm at 0.1 / 0.2 / 0.4 m/s^2).
ACCEL_MAX_M_S2 = 0.2
# A turn is spread over a longer time than the bound needs while its path stays this close to the
# point: a tenth of the ball's radius (plate_geometry.BALL_RADIUS_M), below the controllers'
# tracking error. It lets a densely drawn path (a CSV every 0.1-0.2 s) turn smoothly along its
# whole length without moving it.
CORNER_CUT_M = 0.002


class Waypoints(Reference):
    """Path through timed points (t_i, x_i, y_i), repeating with period_s (inf: not looping).

    Used for the square and the CSV path: straight segments at constant velocity between the
    points, joined at each point by a blend centred on t_i that turns the velocity from the
    segment before to the one after by dv_i (a looping path closes from the last point back to
    the first; one that does not loop rests before its first point and after its last). The
    velocity is continuous and the acceleration bounded. Two kinds of blend (`smooth_blend`):

    - A turn with room on both sides (a square's corner) is smooth: v = v_in + dv_i s(tau),
      s = 3 tau^2 - 2 tau^3, over T_i = max(32 CORNER_CUT_M / (3 |dv_i|), 1.5 |dv_i| /
      ACCEL_MAX_M_S2), the longest turn that passes within CORNER_CUT_M of the point but no
      shorter than the acceleration bound needs. Its acceleration 6 tau (1 - tau) dv_i / T_i
      (at most 1.5 |dv_i| / T_i) starts and ends at zero, so the feed-forward tilt does not
      step; the path passes 3 |dv_i| T_i / 32 from the point at t_i.
    - Where that turn is longer than a neighbouring segment S (a densely drawn path), the
      blend has the constant acceleration dv_i / T_i over T_i = min(max(8 CORNER_CUT_M /
      |dv_i|, |dv_i| / ACCEL_MAX_M_S2), S_prev, S_next) and passes |dv_i| T_i / 8 from the
      point. A path drawn every 0.1-0.2 s gets blends as long as its segments, touching: a
      piecewise-parabolic path through the segments' midpoints whose acceleration follows the
      drawn curvature, changing from one blend to the next as the curvature does.

    No blend is longer than a neighbouring segment, so blends never overlap. The acceleration
    stays within ACCEL_MAX_M_S2 unless a path's points are too close for its turns
    (|dv_i| / ACCEL_MAX_M_S2 longer than a neighbouring segment); `blend_s`, `corner_cut_m`
    and `accel_max_m_s2` give a path's own figures. The points' times are kept.

    With `hold=True` (the step sequence) each point is held until the next time instead.
    """

    def __init__(self, times_s: Sequence[float], points_m: Sequence[Sequence[float]],
                 period_s: float, hold: bool = False):
        self.times_s = np.asarray(times_s, dtype=float)
        self.points_m = np.asarray(points_m, dtype=float).reshape(-1, 2)
        self.period_s, self.hold = period_s, hold
        if not hold:
            self._build_blends()

    def _build_blends(self) -> None:
        """The pieces (blend, straight segment, blend, ...): their start times and, for each, an
        anchor time and the coefficients of p = c0 + c1 dt + ... + c4 dt^4 (dt from the anchor),
        so that sample() is one bisection and a polynomial."""
        times, pts = self.times_s, self.points_m
        n = len(times)
        loop = math.isfinite(self.period_s)
        if loop:   # segment i runs from point i to point i + 1, the last one back to the first
            ends = np.append(times[1:], self.period_s)
            nxt = np.roll(pts, -1, axis=0)
        else:      # the rest before the first point and after the last are segments of infinite length
            ends, nxt = times[1:], pts[1:]
        seg_t = ends - times[:len(ends)]
        seg_v = (nxt - pts[:len(ends)]) / seg_t[:, None]
        if loop:
            v_in, v_out = np.roll(seg_v, 1, axis=0), seg_v
            s_in, s_out = np.roll(seg_t, 1), seg_t
        else:
            v_in = np.vstack([np.zeros((1, 2)), seg_v])
            v_out = np.vstack([seg_v, np.zeros((1, 2))])
            s_in = np.append(math.inf, seg_t)
            s_out = np.append(seg_t, math.inf)
        dv = v_out - v_in
        turn = np.linalg.norm(dv, axis=1)
        room = np.minimum(s_in, s_out)
        with np.errstate(divide="ignore"):
            smooth_t = np.maximum(32.0 * CORNER_CUT_M / (3.0 * turn), 1.5 * turn / ACCEL_MAX_M_S2)
            const_t = np.maximum(8.0 * CORNER_CUT_M / turn, turn / ACCEL_MAX_M_S2)
        smooth = (smooth_t <= room) & (turn > 0)
        blend = np.where(smooth, smooth_t, np.minimum(const_t, room))
        blend = np.where(np.isfinite(blend), blend, 0.0)   # a lone point of a path that does not loop
        safe = np.where(blend > 0, blend, 1.0)
        self.blend_s, self.smooth_blend = blend, smooth
        self.corner_cut_m = np.where(smooth, 3.0 / 32.0, 1.0 / 8.0) * turn * blend   # distance at t_i
        peak = np.where(blend > 0, np.where(smooth, 1.5, 1.0) * turn / safe, 0.0)
        self.accel_max_m_s2 = float(np.max(peak, initial=0.0))
        zero = np.zeros(2)
        starts, pieces = [], []   # pieces: anchor time, then p = c0 + c1 dt + c2 dt^2 + c3 dt^3 + c4 dt^4
        if not loop:   # at rest on the first point until its blend starts
            starts.append(-math.inf)
            pieces.append((0.0, pts[0], zero, zero, zero, zero))
        for i in range(n):
            T = blend[i]
            t0 = times[i] - T / 2.0
            p0 = pts[i] - v_in[i] * T / 2.0
            if smooth[i]:   # v = v_in + dv (3 tau^2 - 2 tau^3): the acceleration 6 tau (1 - tau) dv / T
                blend_piece = (t0, p0, v_in[i], zero, dv[i] / T ** 2, -dv[i] / (2.0 * T ** 3))
            else:           # constant acceleration dv / T
                blend_piece = (t0, p0, v_in[i], dv[i] / (2.0 * safe[i]), zero, zero)
            starts += [t0, times[i] + T / 2.0]             # the blend, then the straight segment
            pieces += [blend_piece, (times[i], pts[i], v_out[i], zero, zero, zero)]
        # as Python floats: a bisection and a polynomial on floats cost a few microseconds per
        # sample (the MPC samples its whole horizon every tick), a third of numpy's on scalars
        self._starts = [float(t) for t in starts]
        self._pieces = [(float(t),) + tuple(float(c[k]) for c in coeffs for k in (0, 1))
                        for t, *coeffs in pieces]
        # a looping path's window starts where the first point's blend does
        self._t_first = self._starts[0] if loop else 0.0

    def sample(self, t_s: float) -> RefSample:
        if self.hold:
            return self._sample_held(t_s)
        t = t_s
        if math.isfinite(self.period_s):
            t = (t_s - self._t_first) % self.period_s + self._t_first
        t0, p0x, p0y, c1x, c1y, c2x, c2y, c3x, c3y, c4x, c4y = \
            self._pieces[max(bisect.bisect_right(self._starts, t) - 1, 0)]
        d = t - t0
        return RefSample(np.array([p0x + d * (c1x + d * (c2x + d * (c3x + d * c4x))),
                                   p0y + d * (c1y + d * (c2y + d * (c3y + d * c4y)))]),
                         np.array([c1x + d * (2.0 * c2x + d * (3.0 * c3x + d * 4.0 * c4x)),
                                   c1y + d * (2.0 * c2y + d * (3.0 * c3y + d * 4.0 * c4y))]),
                         np.array([2.0 * c2x + d * (6.0 * c3x + d * 12.0 * c4x),
                                   2.0 * c2y + d * (6.0 * c3y + d * 12.0 * c4y)]))

    def _sample_held(self, t_s: float) -> RefSample:
        t = t_s % self.period_s if math.isfinite(self.period_s) else t_s
        i = int(np.searchsorted(self.times_s, t, side="right")) - 1
        return RefSample(self.points_m[max(i, 0)].copy(), _z(), _z())

    def path_points(self, n: int = 100) -> np.ndarray:
        return self.points_m.copy() if self.hold else super().path_points(n)


def square(half_side_m: float, period_s: float, centre=(0.0, 0.0)) -> Waypoints:
    """Square of side 2*half_side_m at constant speed, one lap per period_s, its corners
    rounded by Waypoints' blends."""
    _positive(radius_m=half_side_m, period_s=period_s)
    c = np.asarray(centre, dtype=float)
    corners = [c + half_side_m * np.array(p) for p in ((1, -1), (1, 1), (-1, 1), (-1, -1))]
    return Waypoints([period_s * i / 4 for i in range(4)], corners, period_s)


def step_sequence(amplitude_m: float, dwell_s: float, centre=(0.0, 0.0)) -> Waypoints:
    """Steps centre -> +x -> +y -> -x -> -y (each amplitude_m off centre), held dwell_s each."""
    _positive(radius_m=amplitude_m, period_s=dwell_s)
    c = np.asarray(centre, dtype=float)
    pts = [c, c + (amplitude_m, 0), c + (0, amplitude_m), c + (-amplitude_m, 0), c + (0, -amplitude_m)]
    return Waypoints([dwell_s * i for i in range(len(pts))], pts, dwell_s * len(pts), hold=True)


def load_csv_path(path: str | Path, loop: bool = True, max_abs_m: float = USABLE_HALF_WIDTH_M) -> Waypoints:
    """Path from a CSV file with rows `t_s,x_m,y_m` (a header line is allowed; '#' comments).

    Times must increase strictly; coordinates must be finite and within +-max_abs_m.
    Raises ReferenceError naming the file and the bad row. The path passes the rows at their
    times, smoothed at each one as Waypoints states.
    """
    path = Path(path)
    if path.exists() and not path.is_file():  # a pipe would block the node that reads it
        raise ReferenceError(f"reference CSV {path}: not a regular file")
    if path.is_file() and path.stat().st_size > CSV_MAX_BYTES:
        raise ReferenceError(f"reference CSV {path}: {path.stat().st_size / 1e6:.0f} MB, more than a path "
                             f"needs (at most {CSV_MAX_BYTES / 1e6:.0f} MB)")
    try:
        text = read_text_file(path, "reference CSV")
    except TextFileError as error:
        raise ReferenceError(str(error)) from None
    times, points = [], []
    for row_no, row in enumerate(csv.reader(text.splitlines()), start=1):
        if not row or not "".join(row).strip() or row[0].lstrip().startswith("#"):
            continue
        try:
            values = [float(cell) for cell in row]
        except ValueError:
            if row_no == 1 and not times:
                continue  # header
            raise ReferenceError(f"reference CSV {path}: row {row_no} {row!r}: not numbers") from None
        problem = None
        if len(values) != 3:
            problem = f"expected 3 columns t_s,x_m,y_m, got {len(values)}"
        elif not all(math.isfinite(v) for v in values):
            problem = "non-finite value"
        elif max(abs(values[1]), abs(values[2])) > max_abs_m:
            problem = f"point off the usable plate (|x|,|y| <= {max_abs_m} m)"
        elif times and values[0] <= times[-1]:
            problem = "time does not increase"
        if problem:
            raise ReferenceError(f"reference CSV {path}: row {row_no} {row!r}: {problem}")
        times.append(values[0])
        points.append(values[1:])
    if len(times) < 2:
        raise ReferenceError(f"reference CSV {path}: needs at least 2 rows, got {len(times)}")
    t0 = times[0]
    times = [t - t0 for t in times]
    # When looping, the last point returns to the first over one mean segment time.
    period = times[-1] + (times[-1] / (len(times) - 1)) if loop else math.inf
    return Waypoints(times, points, period)


def make_reference(kind: str, radius_m: float = 0.10, period_s: float = 10.0,
                   centre: Tuple[float, float] = (0.0, 0.0), csv_path: str = "") -> Reference:
    """The reference of one kind from KINDS, with the shared size/period/centre parameters.
    A path that leaves the usable plate anywhere is a ReferenceError (a CSV's rows are checked
    as they are read)."""
    if kind == "csv":
        if not csv_path:
            raise ReferenceError("reference 'csv' needs a file: set reference_csv_path")
        return load_csv_path(csv_path)
    reference = _shape(kind, radius_m, period_s, centre)
    points = reference.path_points(PATH_CHECK_POINTS)
    off = np.flatnonzero(~np.all(np.isfinite(points) & (np.abs(points) <= USABLE_HALF_WIDTH_M + 1e-9), axis=1))
    if off.size:
        x, y = points[off[0]]
        raise ReferenceError(f"reference {kind} leaves the usable plate: it reaches ({x:.3f}, {y:.3f}) m, where "
                             f"|x| and |y| must stay within {USABLE_HALF_WIDTH_M} m")
    return reference


def _shape(kind: str, radius_m: float, period_s: float, centre: Tuple[float, float]) -> Reference:
    if kind == "stationary":
        return Stationary(centre)
    if kind == "circle":
        return Circle(radius_m, period_s, centre)
    if kind == "figure_eight":
        return FigureEight(radius_m, period_s, centre)
    if kind == "square":
        return square(radius_m, period_s, centre)
    if kind == "step":
        return step_sequence(radius_m, period_s / 5.0, centre)
    raise ReferenceError(f"unknown reference kind {kind!r}; one of {', '.join(KINDS)}")


def _positive(**values: float) -> None:
    for name, value in values.items():
        if not (math.isfinite(value) and value > 0):
            raise ReferenceError(f"reference {name} = {value!r} must be a positive number")


class Delayed(Reference):
    """Hold `hold_point` for `delay_s`, then blend into `inner` (run from its start) over
    `blend_s` with a smoothstep s(tau) = 3 tau^2 - 2 tau^3, so neither position nor velocity
    jumps (balance at the centre, then track the path):

        p = h + s (q - h),  v = s' (q - h) + s q',  a = s'' (q - h) + 2 s' q' + s q''
    """

    def __init__(self, inner: Reference, delay_s: float, hold_point=(0.0, 0.0), blend_s: float = 0.0):
        self.inner, self.delay_s, self.blend_s = inner, delay_s, blend_s
        self.hold = Stationary(hold_point)
        self.period_s = inner.period_s

    def sample(self, t_s: float) -> RefSample:
        if t_s < self.delay_s:
            return self.hold.sample(t_s)
        q = self.inner.sample(t_s - self.delay_s)
        if self.blend_s <= 0 or t_s >= self.delay_s + self.blend_s:
            return q
        T = self.blend_s
        tau = (t_s - self.delay_s) / T
        s = 3 * tau ** 2 - 2 * tau ** 3
        ds = (6 * tau - 6 * tau ** 2) / T
        dds = (6 - 12 * tau) / T ** 2
        d = q.p - self.hold.centre
        return RefSample(self.hold.centre + s * d, ds * d + s * q.v, dds * d + 2 * ds * q.v + s * q.a)

    def path_points(self, n: int = 100) -> np.ndarray:
        return self.inner.path_points(n)
