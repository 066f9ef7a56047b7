"""sensor_msgs/Image <-> numpy BGR arrays (bgr8 and rgb8), one implementation for every node."""
from __future__ import annotations

from array import array
from typing import Optional, Tuple

import numpy as np
from sensor_msgs.msg import Image


def decode_image(msg: Image) -> Tuple[Optional[np.ndarray], Optional[str]]:
    """sensor_msgs/Image (bgr8/rgb8) -> (H x W x 3 BGR array, None), or (None, why it is unusable).

    A bgr8 image comes back as a view of the message's buffer (no copy)."""
    if msg.encoding not in ("bgr8", "rgb8"):
        return None, f"encoding '{msg.encoding}' (expected bgr8 or rgb8)"
    width, height, step = msg.width, msg.height, msg.step
    if width == 0 or height == 0:
        return None, f"size {width}x{height}"
    if step < 3 * width or len(msg.data) < step * height:
        return None, f"corrupt: {len(msg.data)} bytes for {width}x{height} with step {step}"
    rows = np.frombuffer(msg.data, np.uint8, count=step * height).reshape(height, step)
    image = rows[:, :3 * width].reshape(height, width, 3)
    if msg.encoding == "rgb8":
        return np.ascontiguousarray(image[:, :, ::-1]), None
    return image, None


def encode_image(image_bgr: np.ndarray, stamp_msg, frame_id: str) -> Image:
    """H x W x 3 uint8 BGR array -> sensor_msgs/Image bgr8 (one copy of the pixels)."""
    height, width = image_bgr.shape[:2]
    msg = Image(height=height, width=width, encoding="bgr8", is_bigendian=0, step=3 * width)
    data = array("B")
    data.frombytes(np.ascontiguousarray(image_bgr))   # the field's own type: assigned as is
    msg.data = data
    msg.header.stamp = stamp_msg
    msg.header.frame_id = frame_id
    return msg
