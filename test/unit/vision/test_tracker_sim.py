"""The tracker on frames rendered by the MuJoCo simulation (ball_balance.sim), against its truth."""
import numpy as np
import pytest

from ball_balance import robot
from ball_balance.vision.camera import CameraModel
from ball_balance.vision.config import TrackerConfig
from ball_balance.vision.tracker import BallTracker

sim_world = pytest.importorskip("ball_balance.sim.world")
sim_config = pytest.importorskip("ball_balance.sim.config")
FPS = 30.0


@pytest.fixture(scope="module")
def world():
    w = sim_world.SimWorld()
    yield w
    w.close()


def sim_camera(world) -> CameraModel:
    """Intrinsics as the simulation's /camera/camera_info gives them."""
    cam = world.config.camera
    return CameraModel.pinhole(cam.width_px, cam.height_px, *sim_config.camera_intrinsics(cam))


def locked_tracker(world, **params):
    tracker = BallTracker(TrackerConfig.from_values({"startup_frames": 3, **params}), sim_camera(world))
    world.reset(ball_xy=(0.0, 0.0))
    for i in range(3):
        tracker.process(world.render()[0], i / FPS)
    assert tracker.plate.locked
    return tracker


def test_ball_at_rest_anywhere_on_the_plate_within_2mm(world):
    tracker = locked_tracker(world)
    rng = np.random.default_rng(5)
    errors = []
    for i, (x, y) in enumerate(rng.uniform(-0.19, 0.19, (15, 2))):
        world.place_ball(x, y)
        image, truth = world.render()
        tracker.kalman.reset()                       # independent placements, not a motion
        r = tracker.process(image, (3 + i) / FPS)
        assert r.ball_found and r.tracking_valid and r.markers_found >= 3
        errors.append(np.hypot(r.x - truth.ball.x, r.y - truth.ball.y))
        assert abs(r.pixel_u - truth.pixel_u) < 1.5 and abs(r.pixel_v - truth.pixel_v) < 1.5
    assert 1e3 * np.sqrt(np.mean(np.square(errors))) < 1.0
    assert 1e3 * max(errors) < 2.0


def test_ball_rolling_on_a_tilted_plate_position_and_velocity(world):
    tracker = locked_tracker(world)
    q = list(robot.HOME_POSITIONS_RAD)
    q[3] += 0.04                                      # wrist_1 and wrist_2: tilt the plate
    q[4] += 0.03
    world.set_joint_positions(q)
    world.place_ball(-0.05, 0.05)
    tracker.kalman.reset()                            # the ball was moved by hand
    pos_err, vel_err, speeds = [], [], []
    for i in range(36):
        world.advance(1 / FPS)
        image, truth = world.render()
        r = tracker.process(image, 1.0 + world.time_s)
        b = truth.ball
        assert r.ball_found and r.tracking_valid, i
        if i >= 10:                                   # after the velocity has converged
            pos_err.append(np.hypot(r.x - b.x, r.y - b.y))
            vel_err.append(np.hypot(r.vx - b.vx, r.vy - b.vy))
            speeds.append(np.hypot(b.vx, b.vy))
    assert max(speeds) > 0.1                          # it really rolls
    assert 1e3 * np.sqrt(np.mean(np.square(pos_err))) < 2.0
    assert np.sqrt(np.mean(np.square(vel_err))) < 0.03


def test_arm_link_covering_a_marker_keeps_tracking(world):
    tracker = locked_tracker(world)
    world.place_ball(0.1, -0.1)
    image, truth = world.render()
    image[0:240, 0:320] = 60                          # a dark "hand" over marker 2's corner of the image
    r = tracker.process(image, 4 / FPS)
    assert r.markers_found == 3 and r.ball_found
    assert 1e3 * np.hypot(r.x - truth.ball.x, r.y - truth.ball.y) < 2.0


def test_plate_tilting_under_the_camera_every_frame(world):
    tracker = locked_tracker(world)
    world.place_ball(0.08, -0.06)
    tracker.kalman.reset()
    errors = []
    for i in range(30):
        q = list(robot.HOME_POSITIONS_RAD)
        q[3] += 0.05 * np.sin(2 * np.pi * i / 30)       # the plate rocks at 1 Hz, +-0.05 rad
        q[4] += 0.04 * np.cos(2 * np.pi * i / 30)
        world.set_joint_positions(q)
        world.step(int(round(1 / FPS / world.physics_dt_s)))
        image, truth = world.render()
        r = tracker.process(image, 2.0 + i / FPS)
        assert r.markers_found == 4 and r.ball_found, i
        errors.append(np.hypot(r.x - truth.ball.x, r.y - truth.ball.y))
    assert 1e3 * np.sqrt(np.mean(np.square(errors[5:]))) < 2.0


def test_two_markers_covered_while_the_plate_tilts(world):
    tracker = locked_tracker(world)
    q = list(robot.HOME_POSITIONS_RAD)
    q[3] += 0.04
    q[4] += 0.03
    world.set_joint_positions(q)
    world.place_ball(0.05, -0.1)
    image, truth = world.render()
    image[0:200, :] = 60                                # markers 2 and 3 (top of the image) covered
    tracker.kalman.reset()
    r = tracker.process(image, 1.0)
    assert r.markers_found == 2 and r.ball_found
    assert 1e3 * np.hypot(r.x - truth.ball.x, r.y - truth.ball.y) < 1.5
