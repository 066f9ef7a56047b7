"""The benchmark's camera model: exposure gain, sensor noise, motion blur over the shutter
time and a hand over chosen markers, so vision mode sees what a real camera would."""
import numpy as np
import pytest

from ball_balance.sim.camera import GLOVE_BGR, develop, hand_over_markers
from ball_balance.sim.world import SimWorld


@pytest.fixture(scope="module")
def world():
    world = SimWorld()
    yield world
    world.close()


def test_develop_applies_gain_and_noise_and_keeps_8_bit():
    frame = np.full((40, 50, 3), 100, np.uint8)
    assert develop([frame]) is frame
    assert (develop([frame], gain=1.5) == 150).all()
    noisy = develop([frame], noise_std=5.0, rng=np.random.default_rng(1))
    assert noisy.dtype == np.uint8 and 4.0 < noisy.astype(float).std() < 6.0
    assert develop([frame], gain=4.0).max() == 255


def test_motion_blur_smears_a_rolling_ball_along_its_path(world):
    world.history_s = 0.01
    world.reset()
    world.place_ball(-0.05, 0.0, vx=0.8)
    world.advance(0.05)
    sharp = develop(world.render_exposure(0.0))
    frames = world.render_exposure(0.008)
    blurred = develop(frames)
    assert len(frames) == 5
    orange = lambda image: (image[:, :, 2].astype(int) - image[:, :, 0] > 80)  # noqa: E731
    cols_sharp = np.nonzero(orange(sharp).any(axis=0))[0]
    cols_blur = np.nonzero(((blurred[:, :, 2].astype(int) - blurred[:, :, 0]) > 20).any(axis=0))[0]
    # 0.8 m/s over 8 ms = 6.4 mm: a few pixels longer along x
    assert cols_blur.max() - cols_blur.min() >= cols_sharp.max() - cols_sharp.min() + 3
    world.history_s = 0.0


def test_hand_covers_exactly_the_chosen_markers(world):
    world.reset()
    image, _ = world.render()
    covered = hand_over_markers(image, world, [0, 3])
    glove = np.all(covered == GLOVE_BGR, axis=2)
    for marker_id, expected in ((0, True), (1, False), (2, False), (3, True)):
        from ball_balance.plate_geometry import MARKER_CENTRES_M

        u, v = world.project_plate(*MARKER_CENTRES_M[marker_id])
        assert glove[int(round(v)), int(round(u))] == expected, marker_id
    with pytest.raises(ValueError, match="marker id"):
        hand_over_markers(image, world, [7])
