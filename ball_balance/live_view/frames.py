"""Camera frames to JPEG, on a thread of their own, newest frame only.

The thread takes the newest serialized frame itself (`take`: from a subscription that keeps
only the newest frame and that no executor spins), so the ROS executor's thread never sees a
frame: no callback per frame, nothing decoded or encoded there. It decodes the frame with
`decode` (serialized bytes -> H x W x 3 BGR array, or None), scales it, encodes it with OpenCV
and hands the JPEG to `sink`, at most `rate_hz` times a second and only while active (a page
is connected). Frames arriving in between are replaced in the subscription by newer ones: a
slow machine sends fewer frames, never older ones.
"""
from __future__ import annotations

import threading
import time
from typing import Callable, Optional

import cv2
import numpy as np


def encode_jpeg(image_bgr: np.ndarray, quality: int, scale: float) -> bytes:
    """H x W x 3 BGR -> JPEG bytes, resized by `scale` first (1.0: as it is)."""
    if scale != 1.0:
        height, width = image_bgr.shape[:2]
        size = (max(1, round(width * scale)), max(1, round(height * scale)))
        image_bgr = cv2.resize(image_bgr, size, interpolation=cv2.INTER_AREA)
    ok, buffer = cv2.imencode(".jpg", image_bgr, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError("OpenCV could not encode the frame as JPEG")
    return buffer.tobytes()


class FrameEncoder:
    """A thread that, while active, takes the newest frame with `take` at most `rate_hz` times a
    second, decodes it with `decode`, encodes it and hands the JPEG to `sink`."""

    def __init__(self, take: Callable[[], Optional[bytes]], decode: Callable[[bytes], Optional[np.ndarray]],
                 sink: Callable[[bytes, int, int], None], rate_hz: float, quality: int = 70, scale: float = 1.0,
                 on_error: Callable[[str], None] = lambda why: None):
        self.take, self.decode, self.sink, self.on_error = take, decode, sink, on_error
        self.period_s, self.quality, self.scale = 1.0 / rate_hz, quality, scale
        self.encoded = 0
        self._active, self._stop = threading.Event(), threading.Event()
        self._thread = threading.Thread(target=self._run, name="live-view-jpeg", daemon=True)
        self._thread.start()

    def set_active(self, active: bool) -> None:
        """Encode while True (a page is connected); sleep otherwise."""
        if active:
            self._active.set()
        else:
            self._active.clear()

    def stop(self) -> None:
        self._stop.set()
        self._active.set()
        self._thread.join(timeout=2.0)

    def _run(self) -> None:
        while not self._stop.is_set():
            self._active.wait()
            started = time.monotonic()
            self.encode_newest()
            self._stop.wait(max(0.0, self.period_s - (time.monotonic() - started)))

    def encode_newest(self) -> bool:
        """One round: the newest frame, if any, to the sink; False when none was sent."""
        try:
            serialized = self.take()
            if serialized is None:
                return False
            image = self.decode(serialized)
            if image is None:
                return False
            jpeg = encode_jpeg(image, self.quality, self.scale)
        except Exception as error:  # noqa: BLE001 - a bad frame is reported, the thread goes on
            self.on_error(f"{type(error).__name__}: {error}")
            return False
        self.encoded += 1
        self.sink(jpeg, image.shape[1], image.shape[0])
        return True
