"""The simulated camera rendered and published by a child process (MujocoSystem, camera_process=true).

Why a process: offscreen rendering on the CPU (llvmpipe) costs about 10 ms of CPU per 960x540
frame, and the Python around it (scene update, read-back flip, colour conversion, the image
message and its publishing) holds the interpreter lock for milliseconds per frame: in a
thread of the controller manager it delays the 500 Hz loop. In a child process none of it
touches the manager's interpreter; the kernel schedules rendering like any other process.

- `CameraProcess(model, camera, exposure, publish)`: starts the child (a new interpreter,
  `python -m ball_balance.hardware.camera_process`: no forked locks or GL state);
  `submit(snapshot)` sends the snapshot's time and qpos through a pipe (about 200 bytes,
  never waits for the render); the child renders the newest snapshot and
  drops older ones still queued (counted in `frames_skipped`), so a frame is never rendered
  late while a newer one waits. `frames_rendered`, `frames_skipped`, `last_render_s` and
  `render_cpu_s` (the child's CPU time for all frames) are read from shared memory.
- The child runs normally scheduled: software rendering is the heaviest work of the graph,
  and at a real-time priority it would starve everything else on a small machine. Lock-step
  pacing (ball_balance/sim/lockstep.py) makes a slow frame cost wall time, not control.
- `extra_render_s` > 0: each frame takes that much longer (a slower renderer, for tests and
  benchmarks; camera_extra_render_s).
- `render_threads` > 0: the software renderer's (Mesa llvmpipe's) thread count in the child,
  through LP_NUM_THREADS (camera_render_threads); 0 leaves Mesa's default, one per CPU.
- `publish` (a `PublishSettings`, or None to render only): the child publishes
  /camera/image_raw and /camera/camera_info itself, stamped with the snapshot's time plus
  `stamp_offset_s`, and with `latency_trace` the "rendered" event on /sim/latency_trace.
- The child exits when the parent stops it, closes the pipe or dies; an error in the child
  (no GL backend, a ROS failure) reaches `on_error` in the parent.
"""
from __future__ import annotations

import mmap
import os
import pickle
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Callable, Optional

import numpy as np

from ball_balance.sim.config import CameraConfig

_RENDERED, _SKIPPED, _LAST_RENDER_S, _CPU_S = range(4)
_STATS_BYTES = 4 * 8


@dataclass(frozen=True)
class PublishSettings:
    frame_id: str
    reliable: bool
    stamp_offset_s: float
    latency_trace: bool
    domain_id: Optional[int] = None   # the manager's ROS domain (None: ROS_DOMAIN_ID)


class CameraProcess:
    """Renders (and publishes) submitted snapshots in a child process."""

    def __init__(self, model, camera: CameraConfig, exposure: float, publish: Optional[PublishSettings] = None,
                 on_error: Optional[Callable[[BaseException], None]] = None, render_threads: int = 0,
                 extra_render_s: float = 0.0):
        """render_threads: llvmpipe's threads (0: Mesa's default); extra_render_s: added to
        each frame's render time."""
        # `python -m` rather than multiprocessing's spawn, which re-imports the parent's main
        # module (a script without a __main__ guard would start again in the child)
        self._init = pickle.dumps((model, camera, exposure, publish, extra_render_s))
        stats_fd = os.memfd_create("sim_camera_stats")
        os.ftruncate(stats_fd, _STATS_BYTES)
        self._stats_map = mmap.mmap(stats_fd, _STATS_BYTES)
        self._stats = np.frombuffer(self._stats_map, np.float64)
        snapshots_r, snapshots_w = os.pipe()
        errors_r, errors_w = os.pipe()
        self._child_fds = (stats_fd, snapshots_r, errors_w)
        self._snapshots = Connection(snapshots_w, readable=False)
        self._errors = Connection(errors_r, writable=False)
        self._on_error = on_error
        self._render_threads = render_threads
        self._stopping = False
        self._broken = False
        self._process: Optional[subprocess.Popen] = None
        self._watcher = threading.Thread(target=self._watch, name="sim_camera_watch", daemon=True)

    def start(self) -> None:
        package_root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        env = dict(os.environ)   # this very package, wherever the parent imported it from
        env["PYTHONPATH"] = os.pathsep.join(p for p in (package_root, env.get("PYTHONPATH", "")) if p)
        if self._render_threads > 0:   # Mesa reads it when the child creates its GL context
            env["LP_NUM_THREADS"] = str(self._render_threads)
        self._process = subprocess.Popen(
            [sys.executable, "-m", "ball_balance.hardware.camera_process", *map(str, self._child_fds)],
            stdin=subprocess.PIPE, pass_fds=self._child_fds, env=env)
        for fd in self._child_fds:   # the child holds them now: EOF reaches each side when the other goes
            os.close(fd)
        self._watcher.start()   # hands the model over, then waits for the child's end

    @property
    def frames_rendered(self) -> int:
        return int(self._stats[_RENDERED])

    @property
    def frames_skipped(self) -> int:
        return int(self._stats[_SKIPPED])

    @property
    def last_render_s(self) -> float:
        return float(self._stats[_LAST_RENDER_S])

    @property
    def render_cpu_s(self) -> float:
        return float(self._stats[_CPU_S])

    def submit(self, snapshot) -> None:
        """Send the snapshot's time and pose (real-time loop; a pipe write of ~200 bytes)."""
        if self._broken:
            return
        try:
            self._snapshots.send_bytes(np.concatenate(([snapshot.time_s], snapshot.qpos)).tobytes())
        except (OSError, ValueError):   # the child is gone: the watcher reports why
            self._broken = True

    def stop(self, timeout_s: float = 5.0) -> None:
        self._stopping = True
        try:
            self._snapshots.send_bytes(b"")
            self._snapshots.close()
        except (OSError, ValueError):
            pass
        if self._process is not None:
            try:
                self._process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait(1.0)
        if self._watcher.is_alive():
            self._watcher.join(1.0)

    def _watch(self) -> None:
        message = None
        try:
            self._process.stdin.write(self._init)
            self._process.stdin.close()
            message = self._errors.recv_bytes().decode(errors="replace")
        except (EOFError, OSError):
            pass
        self._broken = True
        if not self._stopping and self._on_error is not None:
            try:
                code = self._process.wait(1.0)
            except subprocess.TimeoutExpired:
                code = None
            self._on_error(RuntimeError(message or f"camera process exited (code {code})"))


def _child_main(stats_fd: int, snapshots_fd: int, errors_fd: int) -> None:
    """The child: render the newest snapshot, publish it, repeat until told to stop."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)   # Ctrl-C reaches the whole group: the parent stops us
    stats = np.frombuffer(mmap.mmap(stats_fd, _STATS_BYTES), np.float64)
    snapshots = Connection(snapshots_fd, writable=False)
    errors = Connection(errors_fd, readable=False)
    publisher = None
    renderer = None
    try:
        model, camera, exposure, publish, extra_render_s = pickle.loads(sys.stdin.buffer.read())
        from ball_balance.sim.camera import CameraRenderer

        renderer = CameraRenderer(model, camera, exposure)
        if publish is not None:
            publisher = _Publisher(camera, publish)
        while True:
            try:
                data = snapshots.recv_bytes()
                while data and snapshots.poll():   # newer ones queued: render only the newest
                    data = snapshots.recv_bytes()
                    stats[_SKIPPED] += 1
            except (EOFError, OSError):
                return   # the parent is gone
            if not data:
                return
            values = np.frombuffer(data, np.float64)
            cpu, start = time.process_time(), time.perf_counter()
            image = renderer.render(values[1:])
            if extra_render_s > 0.0:
                time.sleep(extra_render_s)
            stats[_LAST_RENDER_S] = time.perf_counter() - start
            stats[_CPU_S] += time.process_time() - cpu
            stats[_RENDERED] += 1
            if publisher is not None:
                publisher.publish(image, float(values[0]))
    except Exception as error:  # noqa: BLE001 - reported to the parent
        try:
            errors.send_bytes(f"camera process: {type(error).__name__}: {error}".encode())
        except OSError:
            pass
    finally:
        if renderer is not None:
            renderer.close()
        if publisher is not None:
            publisher.close()


class _Publisher:
    """The child's ROS side: its own context and node, the image topics and the trace."""

    def __init__(self, camera: CameraConfig, settings: PublishSettings):
        import rclpy
        from rclpy.qos import QoSProfile
        from sensor_msgs.msg import CameraInfo, Image
        from std_msgs.msg import Header

        from ball_balance.hardware.sim_ros import IMAGE_RELIABLE, IMAGE_SENSOR_DATA, camera_info_msg

        self.settings = settings
        self.context = rclpy.Context()
        kwargs = {} if settings.domain_id is None else {"domain_id": settings.domain_id}
        rclpy.init(context=self.context, **kwargs)
        self.node = rclpy.create_node("sim_camera", context=self.context)
        qos = IMAGE_RELIABLE if settings.reliable else IMAGE_SENSOR_DATA
        self.image_pub = self.node.create_publisher(Image, "/camera/image_raw", qos)
        self.info_pub = self.node.create_publisher(CameraInfo, "/camera/camera_info", qos)
        self.trace_pub = (self.node.create_publisher(Header, "/sim/latency_trace", QoSProfile(depth=100))
                          if settings.latency_trace else None)
        self.info = camera_info_msg(camera, settings.frame_id)
        self._Header = Header

    def publish(self, image_bgr, time_s: float) -> None:
        from ball_balance.hardware.sim_ros import stamp
        from ball_balance.ros.images import encode_image

        stamp_msg = stamp(time_s + self.settings.stamp_offset_s)
        if self.trace_pub is not None:
            self.trace_pub.publish(self._Header(stamp=stamp_msg, frame_id="rendered"))
        self.image_pub.publish(encode_image(image_bgr, stamp_msg, self.settings.frame_id))
        self.info.header.stamp = stamp_msg
        self.info_pub.publish(self.info)

    def close(self) -> None:
        try:
            self.node.destroy_node()
        finally:
            self.context.try_shutdown()


if __name__ == "__main__":
    _child_main(*map(int, sys.argv[1:4]))
