#!/usr/bin/env python3
"""Simulation speed: real-time factor of physics alone, and of the 500 Hz controller manager
hosting ball_balance/MujocoSystem with the camera at 30/60 Hz, 640x480 and 320x240.

Three kinds of rows:
- physics: SimWorld.step() alone (no manager, no camera);
- manager unpaced: controller_manager_py cycles (joint_state_broadcaster +
  forward_position_controller) back to back in lock-step, camera thread rendering (and,
  with --ros, publishing /camera/image_raw): the highest real-time factor reachable;
- manager paced: the manager's real-time loop (ControlLoop at 500 Hz, as ros2_control_node
  runs it) for --seconds: real-time factor should be 1.0, with overruns and the camera's
  achieved frame rate (rendered frames per simulated second). With pacing=lockstep
  (default) every skipped period is simulated time lost; with pacing=realtime the physics
  catches up with the wall clock after an overrun (like a real arm, which does not wait).

    python benchmarks/sim_bench.py              # all rows, about a minute
    python benchmarks/sim_bench.py --quick      # fewer cycles
"""
from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ball_balance import robot  # noqa: E402
from ball_balance.sim.config import SimConfig  # noqa: E402
from ball_balance.sim.world import SimWorld  # noqa: E402
from controller_manager_py.manager.controller_manager import ControllerManager  # noqa: E402
from controller_manager_py.manager.loop import ControlLoop  # noqa: E402

RATE_HZ = 500
CAMERAS = [(None, 0, 0), (30.0, 640, 480), (60.0, 640, 480), (30.0, 320, 240), (60.0, 320, 240)]


def physics_rtf(dt: float, sim_s: float) -> float:
    world = SimWorld(SimConfig(physics_dt_s=dt))
    steps = int(sim_s / dt)
    start = time.perf_counter()
    world.step(steps)
    return steps * dt / (time.perf_counter() - start)


def make_manager(camera_hz, width, height, node, pacing="lockstep"):
    params = {"camera_enabled": camera_hz is not None, "pacing": pacing}
    if camera_hz is not None:
        params.update(camera_rate_hz=camera_hz, camera_width=width, camera_height=height)
    cm = ControllerManager(RATE_HZ, logger=logging.getLogger("sim_bench"))
    cm.load_robot_description(robot.robot_description("mujoco", params), node=node)
    for name, type_name, ctrl_params in (
            ("joint_state_broadcaster", "joint_state_broadcaster/JointStateBroadcaster", {}),
            ("forward_position_controller", "position_controllers/JointGroupPositionController",
             {"joints": list(robot.JOINT_NAMES)})):
        cm.load_controller(name, type_name, ctrl_params)
        cm.configure_controller(name)
        cm.switch_controller([name], [], 2)
    system = next(iter(cm.rm.components.values())).plugin
    return cm, system


def camera_numbers(system, sim_s):
    camera = system.camera
    if camera is None:
        return "-", "-"
    return f"{camera.frames_rendered / sim_s:5.1f}", f"{camera.last_render_s * 1e3:5.1f}"


def manager_unpaced(camera_hz, width, height, cycles, node):
    cm, system = make_manager(camera_hz, width, height, node)
    period = 1.0 / RATE_HZ
    t0 = system.now()
    start = time.perf_counter()
    for _ in range(cycles):
        now = system.now()
        cm.cycle(now, period)
    wall = time.perf_counter() - start
    sim_s = system.now() - t0
    fps, render_ms = camera_numbers(system, sim_s)
    cm.shutdown()
    return sim_s / wall, fps, render_ms, "-"


def manager_paced(camera_hz, width, height, seconds, node, pacing="lockstep"):
    cm, system = make_manager(camera_hz, width, height, node, pacing)
    loop = ControlLoop(cm)
    t0, start = system.now(), time.perf_counter()
    loop.start()
    time.sleep(seconds)
    loop.stop()
    wall = time.perf_counter() - start
    sim_s = system.now() - t0
    fps, render_ms = camera_numbers(system, sim_s)
    cm.shutdown()
    return sim_s / wall, fps, render_ms, str(loop.skipped_periods)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="shorter runs")
    parser.add_argument("--seconds", type=float, default=5.0, help="length of each paced run (wall s)")
    parser.add_argument("--no-ros", action="store_true", help="do not publish images (no rclpy node)")
    args = parser.parse_args(argv)
    cycles = 1000 if args.quick else 2500
    seconds = 2.0 if args.quick else args.seconds

    node = None
    if not args.no_ros:
        import rclpy

        rclpy.init()
        node = rclpy.create_node("sim_bench")
    rows = []
    for dt in (0.001, 0.002):
        rows.append((f"physics alone, dt {dt * 1e3:.0f} ms", f"{physics_rtf(dt, 5.0 if not args.quick else 2.0):7.1f}",
                     "-", "-", "-"))
    for camera_hz, width, height in CAMERAS:
        label = "no camera" if camera_hz is None else f"camera {camera_hz:.0f} Hz {width}x{height}"
        rtf, fps, render_ms, _ = manager_unpaced(camera_hz, width, height, cycles, node)
        rows.append((f"manager 500 Hz unpaced, {label}", f"{rtf:7.2f}", fps, render_ms, "-"))
    for camera_hz, width, height in CAMERAS:
        label = "no camera" if camera_hz is None else f"camera {camera_hz:.0f} Hz {width}x{height}"
        rtf, fps, render_ms, skipped = manager_paced(camera_hz, width, height, seconds, node)
        rows.append((f"manager 500 Hz paced, {label}", f"{rtf:7.2f}", fps, render_ms, skipped))
    for camera_hz, width, height in CAMERAS[1:3]:
        label = f"camera {camera_hz:.0f} Hz {width}x{height}"
        rtf, fps, render_ms, skipped = manager_paced(camera_hz, width, height, seconds, node, "realtime")
        rows.append((f"manager 500 Hz paced, pacing=realtime, {label}", f"{rtf:7.2f}", fps, render_ms, skipped))
    if node is not None:
        node.destroy_node()
        rclpy.try_shutdown()

    header = ("case", "real-time factor", "camera fps (sim)", "render ms", "skipped periods")
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]
    print(" | ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)))
    print("-+-".join("-" * w for w in widths))
    for row in rows:
        print(" | ".join(str(c).ljust(w) for c, w in zip(row, widths, strict=True)))
    print(f"\nphysics dt 1 ms (manager rows), ros publishing: {not args.no_ros}, MUJOCO_GL egl/osmesa from env")
    return 0


if __name__ == "__main__":
    sys.exit(main())
