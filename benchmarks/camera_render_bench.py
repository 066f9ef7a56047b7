#!/usr/bin/env python3
"""What the simulated camera costs, and whom: CPU per rendered frame, and how late a 2 ms
sleeper in the same process wakes up (as the controller manager's 500 Hz loop does) with no
camera, with the camera in a thread of that process, and in a child process.

1. render cost: `CameraRenderer.render` at 640x480 and 960x540, wall and CPU time per frame
   (`time.process_time`, all threads of this process: llvmpipe's included; less sensitive
   to the machine's load than wall time).
2. interpreter lock: a loop sleeping 2 ms and submitting a snapshot at 60 Hz; its wake-up
   lateness (median, p95, p99, max) with no camera / CameraThread (the image message built
   in the thread, as the manager's camera thread does, without DDS) / CameraProcess (render
   only). The three run in turn, --rounds times, so they see the same load.

    python benchmarks/camera_render_bench.py [--rounds 2] [--seconds 4]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "controller_manager_py"))  # its own package folder

from ball_balance.hardware.camera_process import CameraProcess  # noqa: E402
from ball_balance.hardware.sim_ros import stamp  # noqa: E402
from ball_balance.ros.images import encode_image  # noqa: E402
from ball_balance.sim.camera import CameraRenderer, CameraThread  # noqa: E402
from ball_balance.sim.config import CameraConfig, SimConfig  # noqa: E402
from ball_balance.sim.world import SimWorld  # noqa: E402


def render_cost(width: int, height: int, frames: int = 30) -> str:
    world = SimWorld(SimConfig(camera=CameraConfig(width_px=width, height_px=height)))
    renderer = CameraRenderer(world.model, world.config.camera)
    qpos = world.snapshot().qpos
    renderer.render(qpos)
    walls = []
    cpu0 = time.process_time()
    for _ in range(frames):
        start = time.perf_counter()
        renderer.render(qpos)
        walls.append(time.perf_counter() - start)
    cpu = (time.process_time() - cpu0) / frames
    renderer.close()
    walls = np.array(walls) * 1e3
    return (f"{width}x{height}: CPU {cpu * 1e3:5.1f} ms/frame, wall median {np.median(walls):5.1f} ms, "
            f"p95 {np.percentile(walls, 95):5.1f} ms")


def lateness(world, camera, seconds: float) -> str:
    late, next_frame = [], 0.0
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        start = time.perf_counter()
        if camera is not None and start >= next_frame:
            next_frame = start + 1.0 / 60.0
            camera.submit(world.snapshot())
        time.sleep(0.002)
        late.append(time.perf_counter() - start - 0.002)
    a = np.array(late) * 1e3
    return (f"median {np.median(a):5.2f}  p95 {np.percentile(a, 95):6.2f}  p99 {np.percentile(a, 99):6.2f}  "
            f"max {a.max():6.1f} ms")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--seconds", type=float, default=4.0, help="per case and round")
    args = parser.parse_args(argv)
    print(f"load average {os.getloadavg()[0]:.1f}, MUJOCO_GL={os.environ.get('MUJOCO_GL', 'egl')}")
    print("1. render cost (one frame at a time)")
    for width, height in ((640, 480), (960, 540)):
        print("   " + render_cost(width, height))
    print("2. wake-up lateness of a 2 ms sleeper in this process, camera 960x540 at 60 Hz")
    world = SimWorld(SimConfig(camera=CameraConfig(width_px=960, height_px=540)))

    def build_message(image, snapshot):
        encode_image(image, stamp(snapshot.time_s), "camera_optical_frame")

    for round_ in range(args.rounds):
        print(f"   round {round_ + 1}: no camera      " + lateness(world, None, args.seconds))
        camera = CameraThread(world.model, world.config.camera, 1.0, build_message)
        camera.start()
        print(f"   round {round_ + 1}: camera thread  " + lateness(world, camera, args.seconds)
              + f"  ({camera.frames_rendered} frames)")
        camera.stop()
        camera = CameraProcess(world.model, world.config.camera, 1.0)
        camera.start()
        camera.submit(world.snapshot())
        deadline = time.monotonic() + 60.0
        while camera.frames_rendered == 0 and time.monotonic() < deadline:   # imports, GL set-up
            time.sleep(0.05)
        first = camera.frames_rendered
        print(f"   round {round_ + 1}: camera process " + lateness(world, camera, args.seconds)
              + f"  ({camera.frames_rendered - first} frames)")
        camera.stop()
    print(f"load average {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    sys.exit(main())
