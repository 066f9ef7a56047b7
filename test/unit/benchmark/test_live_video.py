"""The demo video (ball_balance/benchmark/live.py, VideoClip) plays in real time whatever number
of camera frames arrived; each frame's overlay is the recording at the frame's own stamp,
and a frame waits until every topic has been read past it."""
import cv2
import numpy as np

from ball_balance.benchmark.live import Recording, Stamped, VideoClip, overlay_lines


def _frame(value):
    return np.full((96, 128, 3), value, dtype=np.uint8)


def _recording(until_s, ball=lambda t: (0.0, 0.0), target=lambda t: (0.0, 0.0)):
    """Truth at 100 Hz and targets at 50 Hz from 0 s, commands at 50 Hz, read up to until_s."""
    rec = Recording()
    for t in np.arange(0.0, until_s + 1e-9, 0.01):
        rec.truth.add((t, *ball(t), 1.0))
    for t in np.arange(0.0, until_s + 1e-9, 0.02):
        rec.references.add((t, *target(t)))
        rec.commands.add((t, 0.01 * t, 0.0))
    return rec


def test_sparse_frames_are_held_so_the_clip_lasts_as_long_as_the_run(tmp_path):
    fps = 10.0
    path = tmp_path / "clip.mp4"
    clip = VideoClip(path, length_s=5.0, fps=fps)
    # 3 camera frames over 2 s of stamped time (transport dropped the rest)
    for t, value in ((0.0, 0), (0.5, 120), (2.0, 240)):
        clip.offer(t, _frame(value))
    clip.encode_ready(_recording(3.0), final=True)
    assert clip.close() and clip.frames == 3
    video = cv2.VideoCapture(str(path))
    assert video.get(cv2.CAP_PROP_FPS) == fps
    brightness = []
    while True:
        ok, image = video.read()
        if not ok:
            break
        brightness.append(float(image[60:, :, 0].mean()))
    assert len(brightness) == 21  # 2 s at 10 fps, both ends included
    # frame 5 (t = 0.5 s) switches to the second image, frame 20 to the third
    assert brightness[4] < 60 < brightness[5] and brightness[19] < 180 < brightness[20]


def test_the_overlay_is_the_data_at_the_frames_stamp_not_the_latest_read():
    # the ball rolls at 0.1 m/s towards +x, the target moves along y; read up to 4 s
    rec = _recording(4.0, ball=lambda t: (0.1 * t, 0.0), target=lambda t: (0.0, 0.05 * t))
    rec.states.add((0.5, 0.049, 0.001, 1.0, 4.0))      # the tracker's estimate of the 0.5 s frame
    rec.states.add((3.9, 0.39, 0.0, 1.0, 4.0))
    first, second = overlay_lines(rec, 0.506)
    assert "t   0.51 s" in first and "ball ( +50.6,   +0.0) mm" in first and "target (  +0.0,  +25.3) mm" in first
    assert "tracker -" in second and "tilt (+0.29, +0.00) deg" in second
    assert "tracker ( +49.0,   +1.0) mm" in overlay_lines(rec, 0.5)[1]


def test_a_frame_waits_until_every_topic_is_read_past_its_stamp(tmp_path):
    clip = VideoClip(tmp_path / "clip.mp4", length_s=5.0, fps=10.0)
    rec = _recording(1.0)
    clip.offer(0.5, _frame(50))
    clip.offer(1.5, _frame(90))           # the targets and commands have not been read that far
    clip.encode_ready(rec)
    assert clip.frames == 1 and len(clip.pending) == 1
    for t in np.arange(1.02, 2.0, 0.02):
        rec.references.add((t, 0.0, 0.0))
        rec.commands.add((t, 0.0, 0.0))
    for t in np.arange(1.01, 2.0, 0.01):
        rec.truth.add((t, 0.0, 0.0, 1.0))
    clip.encode_ready(rec)
    assert clip.frames == 2 and not clip.pending
    assert clip.close()


def test_frames_before_the_engagement_or_outside_the_window_are_left_out(tmp_path):
    clip = VideoClip(tmp_path / "clip.mp4", length_s=1.05, start_s=1.0, fps=10.0)
    rec = _recording(4.0)
    rec.references = Stamped(3)
    for t in np.arange(1.5, 4.0, 0.02):   # engaged at 1.5 s
        rec.references.add((t, 0.0, 0.0))
    for t in np.arange(0.0, 4.0, 0.05):   # 20 Hz offered, 10 Hz kept
        clip.offer(t, _frame(100))
    clip.encode_ready(rec, final=True)
    assert clip.frames == 6                # 1.5, 1.6, ..., 2.0 s
    assert clip.close()
