"""The overhead camera: offscreen rendering with mujoco.Renderer, off the control thread.

- `CameraRenderer(model, camera_config, exposure)`: owns its own MjData and GL context;
  `render(qpos)` poses the copy and returns an H x W x 3 uint8 BGR image. Use it from one
  thread only (GL contexts are per thread): create it in the thread that renders.
- `CameraThread`: a daemon thread that owns a CameraRenderer; `submit(snapshot)` hands it
  the latest world snapshot through a single slot (never blocks; an unrendered older
  snapshot is replaced and counted as skipped); each rendered frame goes to
  `on_frame(image_bgr, snapshot)` in the camera thread.

The camera model of the benchmark's vision mode (`develop`, `hand_over_markers`): the
rendered frames (several over the shutter time when there is motion blur) are averaged,
scaled by the exposure gain and given Gaussian sensor noise; a gloved hand can be painted
over chosen markers.

MUJOCO_GL selects the backend (egl, else osmesa); `ensure_gl_backend()` picks one that
works when MUJOCO_GL is unset. No ROS import.
"""
from __future__ import annotations

import os
import threading
from typing import Callable, Optional

import cv2
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
        self._rgb = np.empty((camera.height_px, camera.width_px, 3), np.uint8)   # reused every frame

    def render(self, qpos: np.ndarray) -> np.ndarray:
        self.data.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_camlight(self.model, self.data)
        self.renderer.update_scene(self.data, camera=CAMERA_NAME)
        rgb = self.renderer.render(out=self._rgb)
        bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)   # ~20x faster than a numpy channel flip
        return develop([bgr], self.exposure) if self.exposure != 1.0 else bgr

    def close(self) -> None:
        self.renderer.close()


def develop(frames, gain: float = 1.0, noise_std: float = 0.0,
            rng: Optional[np.random.Generator] = None) -> np.ndarray:
    """One 8-bit BGR image from rendered frames: their mean (motion blur when they span the
    shutter time) x `gain` (exposure) + Gaussian noise of `noise_std` grey levels, clipped."""
    if len(frames) == 1 and gain == 1.0 and noise_std <= 0.0:
        return frames[0]
    image = frames[0].astype(np.float32) if len(frames) == 1 else np.mean(np.stack(frames), axis=0, dtype=np.float32)
    if gain != 1.0:
        image *= gain
    if noise_std > 0.0:
        rng = rng if rng is not None else np.random.default_rng()
        image += rng.normal(0.0, noise_std, image.shape).astype(np.float32)
    return np.clip(image + 0.5 if noise_std > 0.0 or len(frames) > 1 else image, 0, 255).astype(np.uint8)


GLOVE_BGR = (90, 70, 60)   # dark blue-grey: not the ball's orange, not a marker's black/white


def hand_over_markers(image: np.ndarray, world, marker_ids, scale: float = 1.6) -> np.ndarray:
    """A copy of `image` with a gloved hand over each marker in `marker_ids`: a filled square
    `scale` times the marker's side around its centre, projected with the world's camera."""
    import cv2

    from ball_balance.plate_geometry import MARKER_CENTRES_M, MARKER_SIDE_M

    out = image.copy()
    half = scale * MARKER_SIDE_M / 2.0
    for marker_id in marker_ids:
        if marker_id not in MARKER_CENTRES_M:
            raise ValueError(f"marker id {marker_id!r}: expected one of {sorted(MARKER_CENTRES_M)}")
        cx, cy = MARKER_CENTRES_M[marker_id]
        corners = [world.project_plate(cx + dx, cy + dy) for dx, dy in
                   ((-half, -half), (half, -half), (half, half), (-half, half))]
        cv2.fillConvexPoly(out, np.round(np.array(corners)).astype(np.int32), GLOVE_BGR)
    return out


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
