"""HSV ball segmentation: centre accuracy and blob rejection."""
import cv2
import numpy as np

from ball_balance.vision.ball_segmentation import BallSegmenter
from ball_balance.vision.synthetic import BALL_BGR, SyntheticScene

ORANGE = dict(hsv_lower=(0, 120, 110), hsv_upper=(25, 255, 255))


def test_centre_is_sub_pixel_on_a_rendered_sphere():
    scene = SyntheticScene()
    image, _ = scene.render((0.0, 0.0), noise_std=2.0)
    blob = BallSegmenter(**ORANGE).find(image)
    u, v = scene.camera.project(np.array([[0.0, 0.0, scene.ball_radius_m]]))[0]
    assert abs(blob.u - u) < 0.2 and abs(blob.v - v) < 0.2
    assert blob.circularity > 0.85


def test_non_round_and_wrong_size_blobs_are_rejected():
    image = np.full((200, 300, 3), 235, np.uint8)
    cv2.rectangle(image, (10, 10), (150, 25), BALL_BGR, -1)           # a bar: not round
    cv2.circle(image, (250, 150), 4, BALL_BGR, -1)                     # too small
    segmenter = BallSegmenter(**ORANGE)
    assert segmenter.find(image, radius_range_px=(8, 30)) is None
    cv2.circle(image, (100, 120), 15, BALL_BGR, -1)
    blob = segmenter.find(image, radius_range_px=(8, 30))
    assert abs(blob.u - 100) < 0.05 and abs(blob.v - 120) < 0.05
    assert abs(blob.radius_px - 15.5) < 1.0


def test_search_window_limits_the_search_and_reports_full_image_pixels():
    image = np.full((200, 300, 3), 235, np.uint8)
    cv2.circle(image, (50, 50), 12, BALL_BGR, -1)
    cv2.circle(image, (220, 140), 12, BALL_BGR, -1)
    blob = BallSegmenter(**ORANGE).find(image, window=(150, 80, 300, 200))
    assert abs(blob.u - 220) < 0.05 and abs(blob.v - 140) < 0.05


def test_hue_band_wrapping_around_180_for_a_red_ball():
    image = np.full((100, 100, 3), 235, np.uint8)
    cv2.circle(image, (50, 50), 12, (40, 20, 220), -1)                 # red, hue ~ 175
    assert BallSegmenter(**ORANGE).find(image) is None
    blob = BallSegmenter((170, 120, 110), (8, 255, 255)).find(image)
    assert blob is not None and abs(blob.u - 50) < 0.05
