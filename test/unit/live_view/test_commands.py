"""What the live view's page may ask for: checked before anything reaches the graph."""
import math

import pytest

from ball_balance.live_view.commands import CommandError, parse

GAINS = ("kp", "ki", "kd", "reference_kind", "reference_centre_m", "reference_radius_m", "reference_period_s")


def test_lifecycle_transitions_carry_their_lifecycle_msgs_ids():
    assert parse({"op": "lifecycle", "transition": "configure"}, GAINS).transition_id == 1
    assert parse({"op": "lifecycle", "transition": "activate"}, GAINS).transition_id == 3
    assert parse({"op": "lifecycle", "transition": "deactivate"}, GAINS).transition_id == 4


def test_emergency_stop_and_reset_are_triggers():
    assert parse({"op": "emergency_stop"}, GAINS).name == "emergency_stop"
    assert parse({"op": "reset_emergency_stop"}, GAINS).op == "trigger"


@pytest.mark.parametrize("request_, words", [
    ({"op": "lifecycle", "transition": "shutdown_now"}, "unknown transition"),
    ({"op": "set_parameters", "values": {"use_sim_time": 1.0}}, "cannot be set from the page"),
    ({"op": "set_parameters", "values": {"kp": math.nan}}, "must be finite"),
    ({"op": "set_parameters", "values": {"kp": "2"}}, "must be a number"),
    ({"op": "set_parameters", "values": {"kp": True}}, "must be a number"),
    ({"op": "set_parameters", "values": {"kp": -1.0}}, "outside"),
    ({"op": "set_parameters", "values": {}}, "non-empty"),
    ({"op": "reference", "kind": "spiral"}, "unknown reference kind"),
    ({"op": "reference", "kind": "circle", "centre_m": [0.5, 0.0]}, "outside"),
    ({"op": "reference", "kind": "circle", "centre_m": [0.0]}, "[x, y]"),
    ({"op": "format_disk"}, "unknown op"),
    (["emergency_stop"], "JSON object"),
])
def test_a_bad_request_is_refused_with_one_line_naming_it(request_, words):
    with pytest.raises(CommandError) as error:
        parse(request_, GAINS)
    assert words in str(error.value)
    assert "\n" not in str(error.value)


def test_a_reference_request_becomes_the_controllers_reference_parameters():
    command = parse({"op": "reference", "kind": "circle", "centre_m": [0.02, -0.01], "radius_m": 0.05,
                     "period_s": 8}, GAINS)
    assert command.op == "set_parameters"
    assert command.values == {"reference_kind": "circle", "reference_centre_m": [0.02, -0.01],
                              "reference_radius_m": 0.05, "reference_period_s": 8.0}
    assert parse({"op": "reference", "kind": "stationary"}, GAINS).values == {"reference_kind": "stationary"}


def test_gains_are_sent_as_floats_and_described():
    command = parse({"op": "set_parameters", "values": {"kp": 2, "kd": 0.5}}, GAINS)
    assert command.values == {"kp": 2.0, "kd": 0.5}
    assert command.describe() == "set kp=2, kd=0.5"
