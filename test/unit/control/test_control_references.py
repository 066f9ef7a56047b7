import math
import os
from pathlib import Path

import numpy as np
import pytest

from ball_balance.control.references import (
    ACCEL_MAX_M_S2,
    CORNER_CUT_M,
    Circle,
    Delayed,
    FigureEight,
    ReferenceError,
    Waypoints,
    load_csv_path,
    make_reference,
    square,
    step_sequence,
)

SPIRAL_CSV = Path(__file__).resolve().parents[3] / "config" / "paths" / "spiral.csv"


@pytest.mark.parametrize("ref", [Circle(0.1, 10.0, (0.01, -0.02)), FigureEight(0.08, 12.0), square(0.05, 8.0)])
def test_velocity_and_acceleration_match_the_path(ref):
    h = 1e-5
    for t in (0.3, 1.7, 4.1, 7.3):
        s, s1, s0 = ref.sample(t), ref.sample(t + h), ref.sample(t - h)
        np.testing.assert_allclose((s1.p - s0.p) / (2 * h), s.v, atol=1e-5)
        np.testing.assert_allclose((s1.v - s0.v) / (2 * h), s.a, atol=1e-4)


def test_circle_has_its_radius_centre_and_period():
    ref = Circle(0.1, 10.0, (0.02, 0.03))
    for t in np.linspace(0, 10, 17):
        assert math.isclose(np.linalg.norm(ref.sample(t).p - (0.02, 0.03)), 0.1, rel_tol=1e-12)
    np.testing.assert_allclose(ref.sample(0.0).p, ref.sample(10.0).p, atol=1e-12)


def test_figure_eight_crosses_the_centre_twice_per_period():
    ref = FigureEight(0.1, 10.0)
    np.testing.assert_allclose(ref.sample(0.0).p, (0, 0), atol=1e-12)
    np.testing.assert_allclose(ref.sample(5.0).p, (0, 0), atol=1e-12)
    assert max(abs(p[0]) for p in ref.path_points(200)) == pytest.approx(0.1, rel=1e-3)


def test_square_rounds_its_corners_and_closes():
    ref = square(0.05, 8.0)
    corners = [(0.05, -0.05), (0.05, 0.05), (-0.05, 0.05), (-0.05, -0.05)]
    turn = 0.1 / 2.0 * math.sqrt(2.0)   # 0.05 m/s along x, then along y
    assert all(ref.smooth_blend)
    for t, corner in zip((0, 2, 4, 6), corners):   # at a corner's time, the blend's middle
        # a smooth turn over 1.5 turn / a_max passes 3 turn T / 32 inside the corner
        inward = -np.sign(corner) * (9 * turn ** 2 / (64 * ACCEL_MAX_M_S2)) / math.sqrt(2.0)
        np.testing.assert_allclose(ref.sample(t).p, np.add(corner, inward), atol=1e-12)
    np.testing.assert_allclose(ref.sample(7.0).p, (0.0, -0.05), atol=1e-12)   # straight between corners
    np.testing.assert_allclose(ref.sample(8.0).p, ref.sample(0.0).p, atol=1e-12)


def _paths():
    """Waypoint paths: the square, the spiral CSV (dense), a path that does not loop, and an
    irregular loop whose short segments limit its blends."""
    return {
        "square": square(0.075, 8.0),
        "spiral": load_csv_path(SPIRAL_CSV),
        "open": Waypoints([0.0, 1.0, 2.5], [(0.0, 0.0), (0.1, 0.0), (0.1, 0.08)], math.inf),
        "irregular": Waypoints([0.0, 0.3, 2.0, 2.4], [(0.0, 0.0), (0.03, 0.01), (0.1, -0.05), (0.08, 0.0)], 4.0),
    }


PATHS = _paths()


def _knots(ref):
    """The times where a blend starts or ends, each point's time, and the loop closure."""
    t, half = ref.times_s, ref.blend_s / 2
    knots = np.concatenate([t - half, t, t + half])
    if math.isfinite(ref.period_s):
        knots = np.concatenate([knots, knots + ref.period_s, [ref.period_s]])
    return np.sort(knots)


@pytest.mark.parametrize("name", PATHS)
def test_waypoint_path_passes_within_the_stated_distance_of_each_point(name):
    ref = PATHS[name]
    eps = 1e-9
    for i, (t, point) in enumerate(zip(ref.times_s, ref.points_m)):
        distance = np.linalg.norm(ref.sample(t).p - point)
        assert distance == pytest.approx(ref.corner_cut_m[i], abs=1e-12)
        # the turn, from the velocities either side of the blend; the cut stays within
        # CORNER_CUT_M unless the acceleration bound needs a longer blend
        half = ref.blend_s[i] / 2 + eps
        turn = np.linalg.norm(ref.sample(t + half).v - ref.sample(t - half).v)
        bound_cut = (9 / 64 if ref.smooth_blend[i] else 1 / 8) * turn ** 2 / ACCEL_MAX_M_S2
        assert distance <= max(CORNER_CUT_M, bound_cut) + 1e-12


def test_square_and_dense_csv_cut_their_points_as_stated():
    sq, spiral = PATHS["square"], PATHS["spiral"]
    np.testing.assert_allclose(sq.corner_cut_m, 9 * (0.075 * math.sqrt(2)) ** 2 / (64 * ACCEL_MAX_M_S2))
    # the dense spiral turns over its whole length: blends as long as its 0.2 s rows, touching
    assert not any(spiral.smooth_blend)
    np.testing.assert_allclose(spiral.blend_s, 0.2)
    assert max(spiral.corner_cut_m) < CORNER_CUT_M / 4


@pytest.mark.parametrize("name", ["square", "spiral"])
def test_the_acceleration_does_not_step_at_a_corner_and_barely_along_a_curve(name):
    ref = PATHS[name]
    eps = 1e-8
    steps = [np.linalg.norm(ref.sample(k + eps).a - ref.sample(k - eps).a) for k in _knots(ref)]
    # the square's smooth turns start and end at zero acceleration; the spiral's constant-
    # acceleration blends touch, and change by what its curvature changes over a row
    assert max(steps) < (1e-6 if name == "square" else 0.1 * ACCEL_MAX_M_S2)


@pytest.mark.parametrize("name", PATHS)
def test_waypoint_position_and_velocity_are_continuous(name):
    ref = PATHS[name]
    eps = 1e-8
    for knot in _knots(ref):
        before, after = ref.sample(knot - eps), ref.sample(knot + eps)
        np.testing.assert_allclose(after.p, before.p, atol=1e-8, err_msg=f"position jumps at {knot}")
        np.testing.assert_allclose(after.v, before.v, atol=1e-6, err_msg=f"velocity jumps at {knot}")


@pytest.mark.parametrize("name", PATHS)
def test_waypoint_blends_do_not_overlap(name):
    ref = PATHS[name]
    t, half = ref.times_s, ref.blend_s / 2
    ends, starts = t + half, t - half
    if math.isfinite(ref.period_s):
        starts = np.append(starts, starts[0] + ref.period_s)
    assert np.all(ends[:len(starts) - 1] <= starts[1:] + 1e-12)


@pytest.mark.parametrize("name", PATHS)
def test_waypoint_acceleration_is_bounded(name):
    ref = PATHS[name]
    span = ref.period_s if math.isfinite(ref.period_s) else ref.times_s[-1] + 2.0
    peak = max(np.linalg.norm(ref.sample(t).a) for t in np.linspace(-1.0, span + 1.0, 4001))
    assert peak <= ref.accel_max_m_s2 + 1e-12
    if name != "irregular":   # its 0.3 s and 0.4 s segments leave no room for the bound's blends
        assert ref.accel_max_m_s2 <= ACCEL_MAX_M_S2 + 1e-12
        assert peak == pytest.approx(ref.accel_max_m_s2, rel=1e-3)


@pytest.mark.parametrize("name", PATHS)
def test_waypoint_velocity_and_acceleration_are_the_derivatives(name):
    ref = PATHS[name]
    h = 1e-5
    knots = _knots(ref)
    span = ref.period_s if math.isfinite(ref.period_s) else ref.times_s[-1] + 1.0
    for t in np.linspace(-0.5, 1.5 * span, 601):
        if np.min(np.abs(knots - t)) < 3 * h or (math.isfinite(ref.period_s)
                                                  and np.min(np.abs((knots - t) % ref.period_s)) < 3 * h):
            continue   # the acceleration steps at a blend's ends
        s, s1, s0 = ref.sample(t), ref.sample(t + h), ref.sample(t - h)
        np.testing.assert_allclose((s1.p - s0.p) / (2 * h), s.v, atol=1e-7)
        np.testing.assert_allclose((s1.v - s0.v) / (2 * h), s.a, atol=1e-6)


def test_waypoint_path_that_does_not_loop_rests_at_its_ends():
    ref = PATHS["open"]
    for t in (-3.0, -0.01 - ref.blend_s[0] / 2):
        np.testing.assert_allclose(ref.sample(t).p, (0.0, 0.0))
        np.testing.assert_allclose(ref.sample(t).v, (0.0, 0.0))
    end = ref.sample(2.5 + ref.blend_s[-1] / 2 + 0.01)
    np.testing.assert_allclose(end.p, (0.1, 0.08), atol=1e-12)
    np.testing.assert_allclose(end.v, (0.0, 0.0), atol=1e-12)


def test_spiral_csv_loads_and_follows_its_curve():
    ref = load_csv_path(SPIRAL_CSV)
    assert ref.period_s == pytest.approx(16.0)
    for t in np.linspace(0.0, 16.0, 161):
        r = 0.065 + 0.035 * math.cos(2 * math.pi * t / 16.0)
        angle = 2 * math.pi * t / 8.0
        assert np.linalg.norm(ref.sample(t).p - (r * math.cos(angle), r * math.sin(angle))) < 0.001


def test_step_sequence_holds_each_point():
    ref = step_sequence(0.05, 2.0)
    assert tuple(ref.sample(1.0).p) == (0.0, 0.0)
    assert tuple(ref.sample(2.5).p) == (0.05, 0.0)
    assert tuple(ref.sample(4.5).p) == (0.0, 0.05)
    assert tuple(ref.sample(2.5).v) == (0.0, 0.0)


def test_csv_path_interpolates(tmp_path):
    f = tmp_path / "path.csv"
    f.write_text("t_s,x_m,y_m\n0,0,0\n1,0.1,0\n2,0.1,0.1\n")
    ref = load_csv_path(f)
    np.testing.assert_allclose(ref.sample(0.5).p, (0.05, 0.0))
    np.testing.assert_allclose(ref.sample(1.5).p, (0.1, 0.05))


@pytest.mark.parametrize("rows, row_no, why", [
    ("0,0,0\n1,abc,0\n", 2, "not numbers"),
    ("0,0,0\n1,0.1\n", 2, "expected 3 columns"),
    ("0,0,0\n1,0.1,0\n1,0.0,0\n", 3, "time does not increase"),
    ("0,0,0\n1,nan,0\n", 2, "non-finite"),
    ("0,0,0\n1,0.5,0\n", 2, "off the usable plate"),
])
def test_csv_bad_row_is_named(tmp_path, rows, row_no, why):
    f = tmp_path / "bad.csv"
    f.write_text(rows)
    with pytest.raises(ReferenceError, match=f"row {row_no} .*{why}"):
        load_csv_path(f)


def test_a_csv_it_cannot_read_is_a_reference_error(tmp_path):
    # a node refuses a ReferenceError at `param set`; anything else ended the node
    binary = tmp_path / "image.csv"
    binary.write_bytes(b"\x89PNG\r\n\x1a\n")
    with pytest.raises(ReferenceError, match="not a UTF-8 text file"):
        load_csv_path(binary)
    with pytest.raises(ReferenceError, match="No such file"):
        load_csv_path(tmp_path / "missing.csv")
    with pytest.raises(ReferenceError, match="not a regular file"):
        load_csv_path(tmp_path)
    fifo = tmp_path / "path.fifo"
    os.mkfifo(fifo)
    with pytest.raises(ReferenceError, match="not a regular file"):   # reading it would block the node
        load_csv_path(fifo)


@pytest.mark.parametrize("kind, radius_m, centre", [
    ("stationary", 0.1, (5.0, -5.0)),
    ("stationary", 0.1, (math.nan, 0.0)),
    ("circle", 0.2, (0.2285, 0.2285)),     # the centre and the radius each within their limits
    ("figure_eight", 0.15, (0.1, 0.0)),
])
def test_a_path_off_the_usable_plate_is_a_reference_error(kind, radius_m, centre):
    with pytest.raises(ReferenceError, match="leaves the usable plate"):
        make_reference(kind, radius_m, 10.0, centre)
    assert make_reference(kind, 0.05, 10.0, (0.1, -0.1)) is not None


def test_make_reference_rejects_unknown_kind_and_bad_radius():
    with pytest.raises(ReferenceError, match="unknown reference kind"):
        make_reference("spiral")
    with pytest.raises(ReferenceError, match="radius_m"):
        make_reference("circle", radius_m=-1.0)
    with pytest.raises(ReferenceError, match="reference_csv_path"):
        make_reference("csv")


def test_delayed_reference_holds_then_starts():
    ref = Delayed(Circle(0.1, 10.0), 3.0, (0.0, 0.0))
    assert tuple(ref.sample(2.9).p) == (0.0, 0.0)
    np.testing.assert_allclose(ref.sample(3.0).p, (0.1, 0.0))


def test_blended_start_has_no_jump_and_consistent_derivatives():
    ref = Delayed(Circle(0.1, 10.0), 3.0, (0.0, 0.0), blend_s=2.0)
    np.testing.assert_allclose(ref.sample(3.0).p, (0.0, 0.0), atol=1e-12)
    np.testing.assert_allclose(ref.sample(5.5).p, Circle(0.1, 10.0).sample(2.5).p)
    h = 1e-5
    for t in (3.2, 4.0, 4.9):
        s, s1, s0 = ref.sample(t), ref.sample(t + h), ref.sample(t - h)
        np.testing.assert_allclose((s1.p - s0.p) / (2 * h), s.v, atol=1e-6)
        np.testing.assert_allclose((s1.v - s0.v) / (2 * h), s.a, atol=1e-5)
