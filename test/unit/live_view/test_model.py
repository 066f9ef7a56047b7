"""What the live view shows: the ball, its recent path, the error against the reference."""
import json
import math

from ball_balance.live_view.model import SAMPLE_PERIOD_S, Ball, LiveModel


def ball(x, y, valid=True):
    return Ball(x=x, y=y, tracking_valid=valid, ball_found=valid, markers_found=4, pixel_u=320.0, pixel_v=240.0)


def test_the_error_is_reference_minus_ball_while_the_controller_publishes_a_reference():
    model = LiveModel(error_window_s=10.0)
    model.on_ball(ball(0.01, 0.0), 1.0)
    assert model.snapshot()["errors"] == []                 # no reference yet: not engaged
    model.on_reference(0.03, -0.02, 1.01)
    model.on_ball(ball(0.01, 0.0), 1.1)
    snap = model.snapshot()
    assert snap["controller"]["engaged"]
    assert snap["errors"] == [[0.0, 0.02, -0.02]]
    model.on_ball(ball(0.01, 0.0), 2.0)                      # the reference stopped 1 s ago
    assert not model.snapshot()["controller"]["engaged"]


def test_histories_keep_one_sample_per_period_over_their_window():
    model = LiveModel(error_window_s=2.0, path_window_s=1.0)
    model.on_reference(0.0, 0.0, 0.0)
    t = 0.0
    while t < 5.0:
        model.on_reference(0.0, 0.0, t)
        model.on_ball(ball(0.01, 0.0), t)
        t += 1 / 60
    snap = model.snapshot()
    assert len(snap["path"]) <= 1.0 / SAMPLE_PERIOD_S + 1
    assert len(snap["errors"]) <= 2.0 / SAMPLE_PERIOD_S + 1
    assert -2.0 - SAMPLE_PERIOD_S <= snap["errors"][0][0] <= -1.9 and snap["errors"][-1][0] <= 0.0


def test_a_non_finite_ball_state_is_refused_and_counted():
    model = LiveModel()
    model.on_ball(ball(0.01, 0.02), 1.0)
    assert not model.on_ball(ball(math.nan, 0.0), 1.1)
    snap = model.snapshot()
    assert snap["refused"] == 1 and snap["ball"]["x"] == 0.01


def test_a_lost_ball_adds_nothing_to_the_path():
    model = LiveModel()
    model.on_ball(ball(0.01, 0.0, valid=False), 1.0)
    assert model.snapshot()["path"] == [] and model.snapshot()["ball"]["tracking_valid"] is False


def test_robot_manager_events_are_kept_newest_first_and_set_its_state():
    model = LiveModel()
    model.on_manager_event(2, "emergency stop called", {"event": "emergency_stop", "source": "service",
                                                        "lifecycle_state": "inactive"}, 5.0)
    model.on_manager_event(0, "reset", {"event": "reset"}, 6.0)
    snap = model.snapshot()["robot_manager"]
    assert [e["event"] for e in snap["events"]] == ["reset", "emergency_stop"]
    assert snap["lifecycle_state"] == "inactive"


def test_the_arm_speed_is_the_fastest_joints():
    model = LiveModel()
    model.on_joint_velocities([0.0, -0.3, 0.1, math.nan], 1.0)
    assert model.snapshot()["arm"]["speed_rad_s"] == 0.3
    model.on_joint_velocities([], 1.1)
    assert model.snapshot()["arm"]["speed_rad_s"] is None


def test_before_anything_arrives_the_state_is_strict_json():
    # a page parses it with JSON.parse, which takes no Infinity or NaN: nothing would show,
    # not even that the robot manager and the controller are absent
    snapshot = LiveModel().snapshot()
    assert json.loads(json.dumps(snapshot, allow_nan=False)) == snapshot
    assert snapshot["arm"] == {"speed_rad_s": None, "age_s": None}
