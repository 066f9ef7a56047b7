"""The demo video plays in real time: its length is the simulated time it covers, whatever
number of camera frames arrived."""
import cv2
import numpy as np

from ball_balance.benchmark.live import write_video


def _frame(value):
    return np.full((48, 64, 3), value, dtype=np.uint8)


def test_sparse_frames_are_held_so_the_clip_lasts_as_long_as_the_run(tmp_path):
    fps = 10.0
    # 3 camera frames over 2 s of simulated time (transport dropped the rest)
    frames = [(0.0, _frame(0), None, None), (0.5, _frame(120), None, None), (2.0, _frame(240), None, None)]
    path = tmp_path / "clip.mp4"
    assert write_video(frames, path, fps)
    video = cv2.VideoCapture(str(path))
    assert video.get(cv2.CAP_PROP_FPS) == fps
    brightness = []
    while True:
        ok, image = video.read()
        if not ok:
            break
        brightness.append(float(image[30:, :, 0].mean()))
    assert len(brightness) == 21  # 2 s at 10 fps, both ends included
    # frame 5 (t = 0.5 s) switches to the second image, frame 20 to the third
    assert brightness[4] < 60 < brightness[5] and brightness[19] < 180 < brightness[20]
