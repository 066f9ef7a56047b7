"""ros/images.image_from_cdr: a serialized sensor_msgs/Image read in place gives what rclpy's
deserialization gives (stamp, frame_id, size, encoding, pixels), for padded rows, both byte
orders and any frame_id length; truncated bytes raise ValueError."""
import struct

import numpy as np
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Image

from ball_balance.ros.images import decode_image, encode_image, image_from_cdr


def _image(width=7, height=5, frame_id="camera", encoding="bgr8", pad=0):
    rng = np.random.default_rng(width * height + pad)
    msg = Image(height=height, width=width, encoding=encoding, step=3 * width + pad)
    msg.header.stamp.sec, msg.header.stamp.nanosec = 1_700_000_123, 456_789_012
    msg.header.frame_id = frame_id
    msg.data = rng.integers(0, 256, (3 * width + pad) * height, dtype=np.uint8).tobytes()
    return msg


@pytest.mark.parametrize("frame_id", ["", "c", "cam", "camera", "camera_optical_frame"])
@pytest.mark.parametrize("encoding,pad", [("bgr8", 0), ("rgb8", 0), ("bgr8", 3), ("rgb8", 1)])
def test_same_fields_and_pixels_as_rclpy(frame_id, encoding, pad):
    msg = _image(frame_id=frame_id, encoding=encoding, pad=pad)
    view = image_from_cdr(serialize_message(msg))
    assert (view.header.stamp.sec, view.header.stamp.nanosec) == (1_700_000_123, 456_789_012)
    assert view.header.frame_id == frame_id
    assert (view.height, view.width, view.encoding, view.step) == (msg.height, msg.width, encoding, msg.step)
    expected, problem = decode_image(msg)
    image, view_problem = decode_image(view)
    assert problem is None and view_problem is None
    assert np.array_equal(image, expected)


def test_a_full_frame_is_not_copied():
    frame = np.random.default_rng(0).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    serialized = serialize_message(encode_image(frame, Image().header.stamp, "camera"))
    image, problem = decode_image(image_from_cdr(serialized))
    assert problem is None and np.array_equal(image, frame)
    assert np.shares_memory(image, np.frombuffer(serialized, np.uint8))


def test_big_endian_cdr():
    pixels = bytes(range(2 * 3 * 2))
    # offsets after the 4-byte encapsulation header: stamp 0, frame_id 8 ("cam\0" at 12),
    # height/width 16, encoding 24 ("bgr8\0" at 28), is_bigendian 33, padding, step 36, data 40
    body = (struct.pack(">iII", 12, 34, 4) + b"cam\x00" + struct.pack(">III", 2, 2, 5) + b"bgr8\x00"
            + b"\x01\x00\x00" + struct.pack(">II", 6, len(pixels)) + pixels)
    view = image_from_cdr(b"\x00\x00\x00\x00" + body)
    assert (view.header.stamp.sec, view.header.stamp.nanosec, view.header.frame_id) == (12, 34, "cam")
    image, problem = decode_image(view)
    assert problem is None and image.tobytes() == pixels


def test_truncated_bytes_raise():
    serialized = serialize_message(_image())
    for cut in (3, 10, 30, len(serialized) - 1):
        with pytest.raises(ValueError, match="truncated"):
            image_from_cdr(serialized[:cut])
