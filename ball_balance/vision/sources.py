"""Frame sources outside ROS: a USB camera (device index or path) or a video file, through
cv2.VideoCapture. The node runs one in a capture thread; tools and benchmarks use it too."""
from __future__ import annotations

import time
from typing import Optional, Tuple

import cv2
import numpy as np


class SourceError(RuntimeError):
    """A camera or file that cannot be opened (the message names it)."""


class CaptureSource:
    """Frames from cv2.VideoCapture, stamped with the wall-clock time they were read.

    `kind` is "camera" (device "0" or "/dev/video0"; width, height, fps are requested, the
    driver may choose others) or "file" (replayed at `rate_hz`, 0 = the file's own rate,
    optionally looping)."""

    def __init__(self, kind: str, location: str, width: int = 640, height: int = 480, fps: float = 30.0,
                 rate_hz: float = 0.0, loop: bool = False, clock=time.time):
        self.kind, self.location, self.loop, self.clock = kind, location, loop, clock
        # OpenCV's own backend warnings would bury our one-line error: quiet while opening
        previous = cv2.utils.logging.getLogLevel()
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
        try:
            self._open(kind, location)
        finally:
            cv2.utils.logging.setLogLevel(previous)
        if kind == "camera":
            self.capture.set(cv2.CAP_PROP_FRAME_WIDTH, width)
            self.capture.set(cv2.CAP_PROP_FRAME_HEIGHT, height)
            self.capture.set(cv2.CAP_PROP_FPS, fps)
            self.period_s = 0.0                      # the camera paces itself
        else:
            file_fps = self.capture.get(cv2.CAP_PROP_FPS) or 30.0
            self.period_s = 1.0 / (rate_hz or file_fps)
        self._next_s: Optional[float] = None
        self.ended = False

    def _open(self, kind: str, location: str) -> None:
        if kind == "camera":
            target = int(location) if location.strip().isdigit() else location
            self.capture = cv2.VideoCapture(target)
            what = f"camera '{location}'"
        elif kind == "file":
            self.capture = cv2.VideoCapture(location)
            what = f"video file '{location}'"
        else:
            raise SourceError(f"unknown source kind '{kind}'")
        if not self.capture.isOpened():
            raise SourceError(f"{what} cannot be opened")

    def read(self) -> Tuple[Optional[np.ndarray], float]:
        """The next frame (BGR) and its stamp (s), or (None, stamp) on a failed read / end."""
        if self.period_s:
            now = time.monotonic()
            if self._next_s is not None and now < self._next_s:
                time.sleep(self._next_s - now)
            self._next_s = max(now, self._next_s or now) + self.period_s
        ok, frame = self.capture.read()
        stamp = self.clock()
        if not ok and self.kind == "file":
            if self.loop:
                self.capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
                ok, frame = self.capture.read()
            else:
                self.ended = True
        return (frame if ok else None), stamp

    def close(self) -> None:
        self.capture.release()
