"""Camera frames to JPEG off the ROS thread: newest frame only, only while active."""
import threading

import cv2
import numpy as np

from ball_balance.live_view.frames import FrameEncoder, encode_jpeg


def test_a_frame_encodes_to_a_jpeg_of_the_scaled_size():
    image = np.zeros((480, 640, 3), np.uint8)
    image[100:200, 300:400] = (0, 128, 255)
    decoded = cv2.imdecode(np.frombuffer(encode_jpeg(image, 70, 0.5), np.uint8), cv2.IMREAD_COLOR)
    assert decoded.shape == (240, 320, 3)
    assert abs(int(decoded[75, 175, 2]) - 255) < 20


def test_the_encoder_sends_only_while_active_and_survives_a_bad_frame():
    frames = [b"bad", b"good"]
    sent, errors = [], []
    done = threading.Event()

    def take():
        return frames.pop(0) if frames else None

    def decode(data):
        if data == b"bad":
            raise ValueError("truncated")
        return np.full((48, 64, 3), 200, np.uint8)

    def sink(jpeg, width, height):
        sent.append((jpeg[:2], width, height))
        done.set()

    encoder = FrameEncoder(take, decode, sink, rate_hz=50.0, on_error=errors.append)
    try:
        assert not done.wait(0.2) and frames == [b"bad", b"good"]   # inactive: nothing taken
        encoder.set_active(True)
        assert done.wait(5.0)
    finally:
        encoder.stop()
    assert sent == [(b"\xff\xd8", 64, 48)]
    assert errors == ["ValueError: truncated"]
