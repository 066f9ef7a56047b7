"""The overhead camera: offscreen rendering with mujoco.Renderer, off the control thread.

- `CameraRenderer(model, camera_config, exposure)`: owns its own MjData and GL context;
  `render(qpos)` poses the copy and returns an H x W x 3 uint8 BGR image. Use it from one
  thread only (GL contexts are per thread): create it in the thread that renders.
- `CameraThread`: a daemon thread that owns a CameraRenderer; `submit(snapshot)` hands it
  the latest world snapshot through a single slot (never blocks; an unrendered older
  snapshot is replaced and counted as skipped); each rendered frame goes to
  `on_frame(image_bgr, snapshot)` in the camera thread.

MUJOCO_GL selects the backend (egl, else osmesa); `ensure_gl_backend()` picks one that
works when MUJOCO_GL is unset. No ROS import.
"""
from __future__ import annotations

import os
import threading
from typing import Callable, Optional

import mujoco
import numpy as np

from ball_balance.sim.config import CameraConfig
from ball_balance.sim.model import CAMERA_NAME


def ensure_gl_backend() -> str:
    """Set MUJOCO_GL to egl when unset (osmesa is the fallback the set-up installs)."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
    return os.environ["MUJOCO_GL"]


class CameraRenderer:
    """Renders the overhead camera for a given qpos (its own MjData; one thread only)."""

    def __init__(self, model: mujoco.MjModel, camera: CameraConfig, exposure: float = 1.0):
        ensure_gl_backend()
        self.model, self.camera, self.exposure = model, camera, exposure
        self.data = mujoco.MjData(model)
        try:
            self.renderer = mujoco.Renderer(model, height=camera.height_px, width=camera.width_px)
        except Exception as error:  # no GL backend: say which one failed
            raise RuntimeError(f"cannot create a MuJoCo renderer with MUJOCO_GL={os.environ.get('MUJOCO_GL')}: "
                               f"{error} (try MUJOCO_GL=osmesa)") from None

    def render(self, qpos: np.ndarray) -> np.ndarray:
        self.data.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_camlight(self.model, self.data)
        self.renderer.update_scene(self.data, camera=CAMERA_NAME)
        rgb = self.renderer.render()
        bgr = np.ascontiguousarray(rgb[:, :, ::-1])
        if self.exposure != 1.0:
            bgr = np.clip(bgr.astype(np.float32) * self.exposure, 0, 255).astype(np.uint8)
        return bgr

    def close(self) -> None:
        self.renderer.close()


class CameraThread:
    """Renders submitted snapshots in its own thread; frames go to `on_frame(image, snapshot)`."""

    def __init__(self, model: mujoco.MjModel, camera: CameraConfig, exposure: float,
                 on_frame: Callable[[np.ndarray, object], None],
                 on_error: Optional[Callable[[BaseException], None]] = None):
        self._args = (model, camera, exposure)
        self._on_frame, self._on_error = on_frame, on_error
        self._slot = None
        self._cond = threading.Condition()
        self._stop = False
        self.frames_rendered = 0
        self.frames_skipped = 0
        self.last_render_s = 0.0
        self._thread = threading.Thread(target=self._run, name="sim_camera", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def submit(self, snapshot) -> None:
        """Hand over the newest snapshot (non-blocking; replaces one not yet rendered)."""
        with self._cond:
            if self._slot is not None:
                self.frames_skipped += 1
            self._slot = snapshot
            self._cond.notify()

    def stop(self, timeout_s: float = 2.0) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify()
        if self._thread.is_alive():
            self._thread.join(timeout_s)

    def _run(self) -> None:
        import time

        try:
            renderer = CameraRenderer(*self._args)
        except Exception as error:  # noqa: BLE001 - reported to the owner
            if self._on_error:
                self._on_error(error)
            return
        try:
            while True:
                with self._cond:
                    while self._slot is None and not self._stop:
                        self._cond.wait()
                    if self._stop:
                        return
                    snapshot, self._slot = self._slot, None
                start = time.perf_counter()
                image = renderer.render(snapshot.qpos)
                self.last_render_s = time.perf_counter() - start
                self.frames_rendered += 1
                self._on_frame(image, snapshot)
        except Exception as error:  # noqa: BLE001 - reported to the owner
            if self._on_error:
                self._on_error(error)
        finally:
            renderer.close()
