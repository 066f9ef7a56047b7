"""Frame sources through cv2.VideoCapture: a video file replayed (looping), clear open errors."""
import cv2
import numpy as np
import pytest

from ball_balance.vision.sources import CaptureSource, SourceError


def test_video_file_frames_then_end_or_loop(tmp_path):
    path = str(tmp_path / "clip.avi")
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 100.0, (64, 48))
    for i in range(3):
        writer.write(np.full((48, 64, 3), 60 * i, np.uint8))
    writer.release()
    once = CaptureSource("file", path)
    frames = [once.read()[0] for _ in range(4)]
    assert [f is not None for f in frames] == [True, True, True, False] and once.ended
    assert frames[0].shape == (48, 64, 3)
    looping = CaptureSource("file", path, loop=True, rate_hz=1000.0)
    assert all(looping.read()[0] is not None for _ in range(7)) and not looping.ended


@pytest.mark.parametrize("kind, location, message", [
    ("file", "/nonexistent/clip.avi", "video file '/nonexistent/clip.avi' cannot be opened"),
    ("camera", "/dev/video_missing", "camera '/dev/video_missing' cannot be opened"),
])
def test_cannot_open_names_the_source(kind, location, message):
    with pytest.raises(SourceError, match=message):
        CaptureSource(kind, location)
