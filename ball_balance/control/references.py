"""References r(t) the ball tracks, in the plate frame [m] (docs/design.md section 6, step 3).

Every reference gives position, velocity and acceleration at time t [s] since it started,
so controllers can use velocity/acceleration feed-forward and preview (MPC). `make_reference`
builds one from the controller's parameters; `path_points` samples one period for display.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence, Tuple

import numpy as np

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


class Waypoints(Reference):
    """Piecewise-linear path through timed points (t_i, x_i, y_i), repeating with period_s.

    Used for the square, the CSV path and (with `hold=True`) the step sequence, where each
    point is held until the next time instead of interpolated.
    """

    def __init__(self, times_s: Sequence[float], points_m: Sequence[Sequence[float]],
                 period_s: float, hold: bool = False):
        self.times_s = np.asarray(times_s, dtype=float)
        self.points_m = np.asarray(points_m, dtype=float).reshape(-1, 2)
        self.period_s, self.hold = period_s, hold

    def sample(self, t_s: float) -> RefSample:
        t = t_s % self.period_s if math.isfinite(self.period_s) else t_s
        times, pts = self.times_s, self.points_m
        i = int(np.searchsorted(times, t, side="right")) - 1
        if i < 0:
            return RefSample(pts[0].copy(), _z(), _z())
        if self.hold or i >= len(times) - 1:
            j = (i + 1) % len(times)
            closing = not self.hold and math.isfinite(self.period_s) and i == len(times) - 1
            if not closing:
                return RefSample(pts[i].copy(), _z(), _z())
            t_next, p_next = self.period_s, pts[j]   # close the loop back to the first point
        else:
            t_next, p_next = times[i + 1], pts[i + 1]
        span = t_next - times[i]
        v = (p_next - pts[i]) / span
        return RefSample(pts[i] + v * (t - times[i]), v, _z())

    def path_points(self, n: int = 100) -> np.ndarray:
        return self.points_m.copy() if self.hold else super().path_points(n)


def square(half_side_m: float, period_s: float, centre=(0.0, 0.0)) -> Waypoints:
    """Square of side 2*half_side_m at constant speed, one lap per period_s."""
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


def load_csv_path(path: str | Path, loop: bool = True, max_abs_m: float = 0.2) -> Waypoints:
    """Path from a CSV file with rows `t_s,x_m,y_m` (a header line is allowed; '#' comments).

    Times must increase strictly; coordinates must be finite and within +-max_abs_m.
    Raises ReferenceError naming the file and the bad row.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as error:
        raise ReferenceError(f"reference CSV {path}: cannot read: {error.strerror}") from None
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
    """The reference of one kind from KINDS, with the shared size/period/centre parameters."""
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
    if kind == "csv":
        if not csv_path:
            raise ReferenceError("reference 'csv' needs a file: set reference_csv_path")
        return load_csv_path(csv_path)
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
