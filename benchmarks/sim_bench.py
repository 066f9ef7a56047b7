#!/usr/bin/env python3
"""Simulation speed: real-time factor of physics alone, and of the 500 Hz controller manager
hosting ball_balance/MujocoSystem with the camera at 30/60 Hz, 640x480, 320x240 and 960x540
(the reference system's camera: 60 Hz at 960x540).

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
    python benchmarks/sim_bench.py --camera-modes   # 960x540 at 60 Hz only: the camera in a child
                                                    # process (default) and in a thread, side by side
    python benchmarks/sim_bench.py --camera-modes --loop-priority 50
                                                    # loop thread and camera process on SCHED_FIFO

"render ms" is the wall time of the last frame's render; "render cpu ms" the camera child
process's CPU time per rendered frame (camera_process=true only), less sensitive to the
machine's load than wall time; "manager cpu s / sim s" the CPU time of this process (the
manager, its loop, and the camera thread when it renders in one) per simulated second.
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "controller_manager_py"))  # its own package folder

from ball_balance import robot  # noqa: E402
from ball_balance.sim.config import SimConfig  # noqa: E402
from ball_balance.sim.world import SimWorld  # noqa: E402
from controller_manager_py.manager.controller_manager import ControllerManager  # noqa: E402
from controller_manager_py.manager.loop import ControlLoop  # noqa: E402

RATE_HZ = 500
CAMERAS = [(None, 0, 0), (30.0, 640, 480), (60.0, 640, 480), (60.0, 960, 540), (30.0, 320, 240), (60.0, 320, 240)]


def physics_rtf(dt: float, sim_s: float) -> float:
    world = SimWorld(SimConfig(physics_dt_s=dt))
    steps = int(sim_s / dt)
    start = time.perf_counter()
    world.step(steps)
    return steps * dt / (time.perf_counter() - start)


def make_manager(camera_hz, width, height, node, pacing="lockstep", camera_process=True):
    params = {"camera_enabled": camera_hz is not None, "pacing": pacing, "camera_process": camera_process}
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


def camera_numbers(system, sim_s, before=(0, 0.0)):
    """(frames per simulated second, last render ms, render CPU ms per frame) since `before`."""
    camera = system.camera
    if camera is None:
        return "-", "-", "-"
    frames = camera.frames_rendered - before[0]
    cpu = getattr(camera, "render_cpu_s", None)
    cpu_ms = f"{(cpu - before[1]) / frames * 1e3:5.1f}" if cpu is not None and frames else "-"
    return f"{frames / sim_s:5.1f}", f"{camera.last_render_s * 1e3:5.1f}", cpu_ms


def camera_ready(system):
    """Wait until the camera has rendered one frame (a child process imports and opens GL first)."""
    camera = system.camera
    if camera is None:
        return (0, 0.0)
    deadline = time.monotonic() + 60.0
    camera.submit(system.world.snapshot())
    while camera.frames_rendered == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    return camera.frames_rendered, getattr(camera, "render_cpu_s", 0.0)


def manager_unpaced(camera_hz, width, height, cycles, node):
    cm, system = make_manager(camera_hz, width, height, node)
    before = camera_ready(system)
    period = 1.0 / RATE_HZ
    t0 = system.now()
    start = time.perf_counter()
    for _ in range(cycles):
        now = system.now()
        cm.cycle(now, period)
    wall = time.perf_counter() - start
    sim_s = system.now() - t0
    numbers = camera_numbers(system, sim_s, before)
    cm.shutdown()
    return (sim_s / wall, *numbers, "-", "-")


def manager_paced(camera_hz, width, height, seconds, node, pacing="lockstep", camera_process=True, loop_priority=0):
    """loop_priority: SCHED_FIFO priority of the loop thread (0: normal)."""
    cm, system = make_manager(camera_hz, width, height, node, pacing, camera_process)
    before = camera_ready(system)
    loop = ControlLoop(cm, thread_priority=loop_priority)
    t0, start, cpu0 = system.now(), time.perf_counter(), time.process_time()
    loop.start()
    time.sleep(seconds)
    loop.stop()
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu0
    sim_s = system.now() - t0
    numbers = camera_numbers(system, sim_s, before)
    cm.shutdown()
    return (sim_s / wall, *numbers, str(loop.skipped_periods), f"{cpu / sim_s:5.2f}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="shorter runs")
    parser.add_argument("--seconds", type=float, default=5.0, help="length of each paced run (wall s)")
    parser.add_argument("--no-ros", action="store_true", help="do not publish images (no rclpy node)")
    parser.add_argument("--camera-modes", action="store_true",
                        help="only 960x540 at 60 Hz, camera in a child process and in a thread, both pacings")
    parser.add_argument("--loop-priority", type=int, default=0,
                        help="SCHED_FIFO priority of the manager's loop thread in paced rows (0: normal)")
    args = parser.parse_args(argv)
    cycles = 1000 if args.quick else 2500
    seconds = 2.0 if args.quick else args.seconds

    node = None
    if not args.no_ros:
        import rclpy

        rclpy.init()
        node = rclpy.create_node("sim_bench")
    rows = []
    if args.camera_modes:
        for pacing in ("lockstep", "realtime"):
            for process in (True, False):
                label = f"pacing={pacing}, camera 60 Hz 960x540 in a {'child process' if process else 'thread'}"
                rtf, *rest = manager_paced(60.0, 960, 540, seconds, node, pacing, process, args.loop_priority)
                rows.append((f"manager 500 Hz paced, {label}", f"{rtf:7.2f}", *rest))
    for dt in (0.001, 0.002) if not args.camera_modes else ():
        rows.append((f"physics alone, dt {dt * 1e3:.0f} ms", f"{physics_rtf(dt, 5.0 if not args.quick else 2.0):7.1f}",
                     "-", "-", "-", "-", "-"))
    full = () if args.camera_modes else CAMERAS
    for camera_hz, width, height in full:
        label = "no camera" if camera_hz is None else f"camera {camera_hz:.0f} Hz {width}x{height}"
        rtf, *rest = manager_unpaced(camera_hz, width, height, cycles, node)
        rows.append((f"manager 500 Hz unpaced, {label}", f"{rtf:7.2f}", *rest))
    for camera_hz, width, height in full:
        label = "no camera" if camera_hz is None else f"camera {camera_hz:.0f} Hz {width}x{height}"
        rtf, *rest = manager_paced(camera_hz, width, height, seconds, node, loop_priority=args.loop_priority)
        rows.append((f"manager 500 Hz paced, {label}", f"{rtf:7.2f}", *rest))
    for camera_hz, width, height in full[1:4]:
        label = f"camera {camera_hz:.0f} Hz {width}x{height}"
        rtf, *rest = manager_paced(camera_hz, width, height, seconds, node, "realtime",
                                   loop_priority=args.loop_priority)
        rows.append((f"manager 500 Hz paced, pacing=realtime, {label}", f"{rtf:7.2f}", *rest))
    if node is not None:
        node.destroy_node()
        rclpy.try_shutdown()

    header = ("case", "real-time factor", "camera fps (sim)", "render ms", "render cpu ms", "skipped periods",
              "manager cpu s / sim s")
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]
    print(" | ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)))
    print("-+-".join("-" * w for w in widths))
    for row in rows:
        print(" | ".join(str(c).ljust(w) for c, w in zip(row, widths, strict=True)))
    print(f"\nphysics dt 1 ms (manager rows), ros publishing: {not args.no_ros}, MUJOCO_GL egl/osmesa from env, "
          f"load average {os.getloadavg()[0]:.1f}; SCHED_FIFO loop {args.loop_priority or 'off'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
