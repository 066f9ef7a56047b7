import math

import numpy as np
import pytest

from ball_balance.control.references import (
    Circle,
    Delayed,
    FigureEight,
    ReferenceError,
    load_csv_path,
    make_reference,
    square,
    step_sequence,
)


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


def test_square_visits_its_corners_and_closes():
    ref = square(0.05, 8.0)
    assert [tuple(np.round(ref.sample(t).p, 6)) for t in (0, 2, 4, 6)] == [
        (0.05, -0.05), (0.05, 0.05), (-0.05, 0.05), (-0.05, -0.05)]
    np.testing.assert_allclose(ref.sample(7.0).p, (0.0, -0.05), atol=1e-12)
    np.testing.assert_allclose(ref.sample(8.0).p, ref.sample(0.0).p, atol=1e-12)


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
