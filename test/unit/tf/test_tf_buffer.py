"""TF buffer on known chains: composition, inverse, interpolation, errors, static vs dynamic."""
import math
import subprocess
import sys

import pytest

from ball_balance.tf import (
    BufferCore,
    ConnectivityException,
    ExtrapolationException,
    LookupException,
    Transform,
    quat_from_euler,
    quat_to_euler,
    slerp,
)

S = 1_000_000_000  # ns per second


def yaw(angle, xyz=(0.0, 0.0, 0.0)):
    return Transform(tuple(float(c) for c in xyz), quat_from_euler(0.0, 0.0, angle))


def close(a, b, tol=1e-9):
    return all(abs(x - y) <= tol for x, y in zip(a, b, strict=True))


def test_pure_part_does_not_import_rclpy():
    code = "import sys, ball_balance.tf; sys.exit('rclpy' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], timeout=60).returncode == 0


def test_composition_maps_points_through_the_chain():
    # world -> arm: 1 m along x, turned 90 deg about z; arm -> plate: 0.5 m along the arm's x
    T_world_arm = yaw(math.pi / 2, (1, 0, 0))
    T_arm_plate = Transform((0.5, 0.0, 0.0))
    T_world_plate = T_world_arm * T_arm_plate
    assert close(T_world_plate.translation, (1.0, 0.5, 0.0))
    assert close(T_world_plate.apply((0.1, 0.0, 0.0)), (1.0, 0.6, 0.0))


def test_inverse_undoes_the_transform():
    T = Transform((0.3, -0.2, 1.1), quat_from_euler(0.3, -0.7, 2.0))
    assert (T * T.inverse()).is_close(Transform())
    assert (T.inverse() * T).is_close(Transform())
    p = (0.4, 0.5, -0.6)
    assert close(T.inverse().apply(T.apply(p)), p)


def test_euler_round_trip_and_slerp_halfway():
    rpy = (0.1, -0.4, 2.5)
    assert close(quat_to_euler(quat_from_euler(*rpy)), rpy)
    half = slerp(quat_from_euler(0, 0, 0.0), quat_from_euler(0, 0, 1.0), 0.5)
    assert close(quat_to_euler(half), (0.0, 0.0, 0.5))


def test_lookup_through_common_ancestor_both_directions():
    buf = BufferCore()
    buf.set_transform("world", "base", 0, Transform((0, 0, 1.0)), static=True)
    buf.set_transform("base", "camera", 0, yaw(math.pi, (0.2, 0, 0)), static=True)
    buf.set_transform("base", "plate", 0, Transform((0.5, 0, 0)), static=True)
    T_camera_plate, _ = buf.lookup_transform("camera", "plate")
    # plate is 0.3 m ahead of the camera in base x; the camera faces -x so it is at -0.3 in camera x
    assert close(T_camera_plate.translation, (-0.3, 0.0, 0.0))
    T_plate_camera, _ = buf.lookup_transform("plate", "camera")
    assert T_plate_camera.is_close(T_camera_plate.inverse())
    T_world_camera, _ = buf.lookup_transform("world", "camera")
    assert close(T_world_camera.translation, (0.2, 0.0, 1.0))
    identity, _ = buf.lookup_transform("plate", "plate")
    assert identity.is_close(Transform())


def test_interpolates_translation_linearly_and_rotation_by_slerp():
    buf = BufferCore()
    buf.set_transform("world", "ball", 1 * S, yaw(0.0, (0, 0, 0)))
    buf.set_transform("world", "ball", 2 * S, yaw(1.0, (1.0, 2.0, 0)))
    T, stamp = buf.lookup_transform("world", "ball", int(1.25 * S))
    assert stamp == int(1.25 * S)
    assert close(T.translation, (0.25, 0.5, 0.0))
    assert close(quat_to_euler(T.rotation), (0.0, 0.0, 0.25))


def test_latest_available_is_the_newest_common_time_of_the_chain():
    buf = BufferCore()
    buf.set_transform("world", "arm", 1 * S, Transform((0, 0, 0)))
    buf.set_transform("world", "arm", 3 * S, Transform((2.0, 0, 0)))
    buf.set_transform("arm", "tool", 2 * S, Transform((0, 1.0, 0)))
    buf.set_transform("tool", "plate", 0, Transform((0, 0, 0.1)), static=True)
    T, stamp = buf.lookup_transform("world", "plate")  # time 0 = latest available
    assert stamp == 2 * S  # the tool edge has nothing newer
    assert close(T.translation, (1.0, 1.0, 0.1))  # arm interpolated at t = 2 s


def test_extrapolation_errors_name_frames_and_times():
    buf = BufferCore()
    buf.set_transform("world", "ball", 1 * S, Transform())
    buf.set_transform("world", "ball", 2 * S, Transform())
    with pytest.raises(ExtrapolationException) as future:
        buf.lookup_transform("world", "ball", 3 * S)
    text = str(future.value)
    assert "future" in text and "[ball]" in text and "[world]" in text
    assert "3.000000" in text and "2.000000" in text
    with pytest.raises(ExtrapolationException, match="past.*0.500000.*1.000000"):
        buf.lookup_transform("world", "ball", S // 2)


def test_static_transforms_hold_at_every_time_dynamic_ones_do_not():
    buf = BufferCore()
    buf.set_transform("world", "camera", 5 * S, Transform((0, 0, 2.0)), static=True)
    T, _ = buf.lookup_transform("world", "camera", 1000 * S)
    assert close(T.translation, (0, 0, 2.0))
    buf.set_transform("world", "ball", 5 * S, Transform((1.0, 0, 0)))
    with pytest.raises(ExtrapolationException):
        buf.lookup_transform("world", "ball", 1000 * S)


def test_unknown_frame_and_disconnected_trees_are_clear_errors():
    buf = BufferCore()
    buf.set_transform("world", "base", 0, Transform(), static=True)
    buf.set_transform("map", "robot", 0, Transform(), static=True)
    with pytest.raises(LookupException, match=r"\[plate\].*source_frame.*known frames: base, map"):
        buf.lookup_transform("world", "plate")
    with pytest.raises(ConnectivityException, match=r"\[base\].*\[robot\].*same tree"):
        buf.lookup_transform("base", "robot")
    assert not buf.can_transform("base", "robot")
    assert buf.can_transform("world", "base")


def test_cache_keeps_only_recent_history():
    buf = BufferCore(cache_time_s=1.0)
    for i in range(50):
        buf.set_transform("world", "ball", i * S // 10, Transform((i, 0, 0)))
    with pytest.raises(ExtrapolationException, match="past"):
        buf.lookup_transform("world", "ball", 1 * S)
    T, _ = buf.lookup_transform("world", "ball", int(4.85 * S))
    assert close(T.translation, (48.5, 0, 0))


def test_leading_slash_is_ignored_and_bad_quaternions_refused():
    buf = BufferCore()
    buf.set_transform("/world", "/base", 0, Transform((1, 0, 0)), static=True)
    assert buf.lookup_transform("world", "base")[0].translation == (1.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="quaternion"):
        Transform.from_values((0, 0, 0), (0, 0, 0, 0))
    with pytest.raises(ValueError, match="finite"):
        Transform.from_values((math.nan, 0, 0), (0, 0, 0, 1))


def test_time_travel_through_a_fixed_frame():
    buf = BufferCore()
    # the camera moves along world x: at 1 s it is at x = 1, at 2 s at x = 2
    buf.set_transform("world", "camera", 1 * S, Transform((1.0, 0, 0)))
    buf.set_transform("world", "camera", 2 * S, Transform((2.0, 0, 0)))
    # where the camera was at 1 s, seen from the camera at 2 s: 1 m behind it
    T = buf.lookup_transform_full("camera", 2 * S, "camera", 1 * S, "world")
    assert close(T.translation, (-1.0, 0.0, 0.0))
