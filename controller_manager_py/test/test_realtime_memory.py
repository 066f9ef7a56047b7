"""realtime.reuse_freed_memory: glibc accepts the settings; large buffers still work."""
import platform

import numpy as np
import pytest

from controller_manager_py.realtime import reuse_freed_memory


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallopt is glibc's")
def test_glibc_accepts_and_frame_sized_buffers_still_allocate():
    assert reuse_freed_memory() is True
    for _ in range(20):                      # frame-sized blocks allocated and freed in turn
        frame = np.ones((480, 640, 3), np.uint8)
        assert int(frame.sum()) == 480 * 640 * 3
