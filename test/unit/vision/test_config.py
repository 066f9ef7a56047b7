"""Tracker parameters: schema defaults are the plate geometry's, bad values name the parameter."""
import pytest

from ball_balance import plate_geometry as pg
from ball_balance.vision.config import TrackerConfig
from controller_manager_py.parameters import ParameterError


def test_defaults_come_from_plate_geometry():
    config = TrackerConfig.from_values()
    assert config.geometry == pg.PlateGeometry()
    assert config.ball_radius_m == pg.BALL_RADIUS_M and config.rolling_factor == pg.ROLLING_FACTOR_SHELL


@pytest.mark.parametrize("values, name", [
    ({"hsv_lower": [0, 300, 0]}, "hsv_lower"),
    ({"ball_radius_range_m": [0.03, 0.01]}, "ball_radius_range_m"),
    ({"marker_ids": [0, 1, 99, 3]}, "marker_ids"),
    ({"marker_x_m": [0.1, 0.2]}, "marker_x_m"),
    ({"gate_sigma": 0.0}, "gate_sigma"),
    ({"max_coast_frames": "five"}, "max_coast_frames"),
])
def test_bad_values_raise_one_line_naming_the_parameter(values, name):
    with pytest.raises(ParameterError, match=name) as error:
        TrackerConfig.from_values(values)
    assert "\n" not in str(error.value)
