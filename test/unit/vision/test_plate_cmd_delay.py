"""The tracker's estimate of the command -> plate delay from the plate's measured tilt
(control/prediction.py StampedDelayEstimator, vision/kalman.py CommandDelayFromTilt)."""
import numpy as np
import pytest

from ball_balance.control.kinematics import PlateKinematics
from ball_balance.control.prediction import StampedDelayEstimator
from ball_balance.rotations import rotvec_to_matrix
from ball_balance.vision.kalman import CommandDelayFromTilt, PlateCommandInput, plate_tilt_rad

CONTROL_DT_S = 0.02


def command(t):
    """A controller's tilts (rad): slow sway plus faster corrections on both axes."""
    return np.array([0.02 * np.sin(2.1 * t) + 0.008 * np.sin(9.0 * t + 1.0),
                     0.015 * np.cos(1.3 * t) + 0.006 * np.sin(7.0 * t)])


def plate_rotation(u, R_camera):
    """The plate's rotation in a camera frame for the tilt pair u (control/kinematics.py wiring)."""
    return R_camera @ rotvec_to_matrix(PlateKinematics.plate_rotvec(*u))


def run(delay_s, duration_s=8.0, start_s=0.05, noise_rad=0.0015, drop=0.1, jitter_s=0.002, seed=3,
        R_camera=None, amplitude=1.0, gap=(4.0, 5.0)):
    """Commands every CONTROL_DT_S; frames at 30 Hz with drops, stamp jitter and a stretch of
    lost markers (`gap`); returns the estimate."""
    rng = np.random.default_rng(seed)
    if R_camera is None:      # a camera neither level nor looking straight down, and rolled
        R_camera = np.diag([1.0, -1.0, -1.0]) @ rotvec_to_matrix([0.25, -0.15, 0.6])
    commands = PlateCommandInput(5.886, delay_s=start_s)
    estimate = CommandDelayFromTilt(commands, StampedDelayEstimator(start_s))
    frame_t = 0.0
    for tick in range(int(duration_s / CONTROL_DT_S)):
        t = tick * CONTROL_DT_S
        commands.add(*(amplitude * command(t)), t)
        while frame_t <= t:
            capture = frame_t
            frame_t += 1.0 / 30.0
            if rng.random() < drop or gap[0] <= capture < gap[1]:
                continue
            # the plate holds the command that was in force delay_s before the capture
            held = np.floor((capture - delay_s) / CONTROL_DT_S) * CONTROL_DT_S
            u = amplitude * command(held)      # at the first frame too: the reference pose is tilted
            R = plate_rotation(u, R_camera) @ rotvec_to_matrix(rng.normal(0.0, noise_rad, 3))
            estimate.add_rotation(capture + rng.normal(0.0, jitter_s), R)
    return estimate


def test_plate_tilt_in_the_commands_convention_whatever_the_camera():
    R_camera = rotvec_to_matrix([0.3, 0.2, -1.0])
    R_ref = plate_rotation((0.0, 0.0), R_camera)
    assert plate_tilt_rad(R_ref, plate_rotation((0.04, -0.07), R_camera)) == pytest.approx((0.04, -0.07), abs=1e-3)


@pytest.mark.parametrize("delay_s", [0.02, 0.09, 0.2])
def test_known_delay_recovered_from_irregular_noisy_frames_and_a_tilted_camera(delay_s):
    estimate = run(delay_s)
    assert estimate.estimator.converged
    assert estimate.delay_s == pytest.approx(delay_s, abs=0.012)
    assert estimate.commands.delay_s == estimate.delay_s      # what the filter's look-up uses
    assert estimate.estimator.correlation > 0.8


def test_scale_and_reference_offset_do_not_move_the_estimate():
    # the reference pose (the first) is a tilted plate, and the plate reaches 60 % of the command
    estimate = run(0.12, amplitude=0.6, start_s=0.0)
    assert estimate.delay_s == pytest.approx(0.12, abs=0.012)


def test_still_plate_keeps_the_current_value():
    estimate = run(0.15, amplitude=0.05, start_s=0.04)       # commands of about 1 mrad: no excitation
    assert not estimate.estimator.converged
    assert estimate.delay_s == 0.04


def test_pose_noise_without_a_match_keeps_the_current_value():
    # a pose far noisier than the tilts it should show: no delay correlates, nothing taken in
    estimate = run(0.1, noise_rad=0.2, start_s=0.07)
    assert estimate.delay_s == 0.07


def test_no_commands_no_estimate():
    commands = PlateCommandInput(5.886, delay_s=0.03)
    estimate = CommandDelayFromTilt(commands, StampedDelayEstimator(0.03))
    for i in range(200):
        estimate.add_tilt(i / 30.0, (0.01 * np.sin(i / 5.0), 0.0))
    assert estimate.delay_s == 0.03 and not estimate.estimator.converged


def test_estimator_ignores_repeated_stamps_and_restarts_when_the_clock_goes_back():
    est = StampedDelayEstimator(0.05, window_s=1.0)
    def history():
        return np.array([0.0, 1.0]), np.zeros((2, 2))

    est.add(0.5, (0.0, 0.0), history)
    est.add(0.5, (1.0, 1.0), history)
    assert len(est._t) == 1
    est.add(-5.0, (0.0, 0.0), history)
    assert list(est._t) == [-5.0]


def test_tracker_measures_the_delay_from_rendered_frames_of_a_tilting_plate():
    from ball_balance.vision.camera import CameraModel
    from ball_balance.vision.config import TrackerConfig
    from ball_balance.vision.synthetic import SyntheticCamera, SyntheticScene
    from ball_balance.vision.tracker import BallTracker

    delay_s = 0.1
    scene = SyntheticScene(SyntheticCamera(camera_tilt_rad=(0.06, -0.04), camera_height_m=0.75))
    cam = scene.camera
    tracker = BallTracker(TrackerConfig.from_values({"startup_frames": 3, "plate_cmd_delay_s": 0.02}),
                          CameraModel(cam.width, cam.height, cam.K, np.zeros(5)))
    off = BallTracker(TrackerConfig.from_values({"startup_frames": 3, "plate_cmd_delay_s": 0.02,
                                                 "estimate_plate_cmd_delay": False}),
                      CameraModel(cam.width, cam.height, cam.K, np.zeros(5)))
    rng = np.random.default_rng(5)
    for i in range(150):
        t = i / 30.0
        for tick in range(int(np.ceil((t - 1.0 / 30.0) / CONTROL_DT_S)), int(np.floor(t / CONTROL_DT_S)) + 1):
            if tick >= 0:
                for tr in (tracker, off):
                    tr.set_plate_cmd(*command(tick * CONTROL_DT_S), tick * CONTROL_DT_S)
        u_x, u_y = command(np.floor((t - delay_s) / CONTROL_DT_S) * CONTROL_DT_S)
        cam.set_plate_tilt(u_y, -u_x)          # rotation_xy(about x, about y) ~ rotvec (u_y, -u_x, 0)
        image, _ = scene.render((0.0, 0.0), rng=rng, noise_std=2.0)
        tracker.process(image, t)
        off.process(image, t)
    assert tracker.plate_cmd_delay.estimator.converged
    assert tracker.plate_cmds.delay_s == pytest.approx(delay_s, abs=0.015)
    assert off.plate_cmd_delay is None and off.plate_cmds.delay_s == 0.02
