"""Ball tracker benchmark: per-stage time, accuracy against truth, detection rate, latency.

1. Time per frame by stage (median, p99) at 640x480 and 960x540 on one core
   (cv2.setNumThreads(1)), synthetic frames of a rolling ball with sensor noise.
2. Position RMSE at rest and rolling, velocity RMSE, detection rate: synthetic frames
   (known camera) and, when ball_balance.sim is importable, MuJoCo-rendered frames with the
   simulation's truth (intrinsics as its /camera/camera_info gives them).
The tracker as a process over DDS (frames answered, image stamp -> /ball_state latency,
per-stage times): benchmarks/transport_bench.py; in the live graph, camera capture -> joint
command: benchmarks/latency_budget_bench.py.

usage: python benchmarks/tracker_bench.py [--timing-frames 600] [--no-sim]
"""
from __future__ import annotations

import argparse

import cv2
import numpy as np

from ball_balance import robot
from ball_balance.vision.camera import CameraModel
from ball_balance.vision.config import TrackerConfig
from ball_balance.vision.synthetic import SyntheticCamera, SyntheticScene
from ball_balance.vision.tracker import STAGES, BallTracker

FPS = 30.0


def pct(values, q):
    return float(np.percentile(values, q)) if len(values) else float("nan")


def rms(values):
    return float(np.sqrt(np.mean(np.square(values)))) if len(values) else float("nan")


def circle_path(n, radius=0.15, revs=1.0):
    """One closed revolution (so frames can be cycled): positions and velocities."""
    w = 2 * np.pi * revs * FPS / n
    t = np.arange(n) / FPS
    pos = np.column_stack([radius * np.cos(w * t), radius * np.sin(w * t)])
    vel = np.column_stack([-radius * w * np.sin(w * t), radius * w * np.cos(w * t)])
    return pos, vel


def calibrated(camera) -> CameraModel:
    return CameraModel(camera.width, camera.height, camera.K, np.zeros(5))


# -- 1. timing -------------------------------------------------------------------------------
def timing(width, height, frames):
    scene = SyntheticScene(SyntheticCamera(width=width, height=height))
    pos, _ = circle_path(60)
    rng = np.random.default_rng(0)
    images = [scene.render(tuple(p), noise_std=2.0, rng=rng)[0] for p in pos]
    tracker = BallTracker(TrackerConfig.from_values(), calibrated(scene.camera))
    per_stage = {s: [] for s in STAGES}
    for i in range(frames + 20):
        r = tracker.process(images[i % len(images)], i / FPS)
        if i >= 20:                                     # after start-up (plate locked)
            for s in STAGES:
                per_stage[s].append(1e3 * r.timings_s[s])
    return per_stage


# -- 2. accuracy -----------------------------------------------------------------------------
class Score:
    def __init__(self):
        self.pos, self.vel, self.frames, self.found = [], [], 0, 0

    def add(self, r, x, y, vx=None, vy=None, score_position=True):
        self.frames += 1
        self.found += r.ball_found
        if r.tracking_valid and score_position:
            self.pos.append(np.hypot(r.x - x, r.y - y))
            if vx is not None:
                self.vel.append(np.hypot(r.vx - vx, r.vy - vy))

    def row(self, name):
        return (f"{name:<28} {1e3 * rms(self.pos):8.2f} {1e3 * max(self.pos, default=np.nan):8.2f} "
                f"{rms(self.vel) if self.vel else float('nan'):9.3f} {100.0 * self.found / max(self.frames, 1):8.1f} "
                f"{self.frames:7d}")


def synthetic_accuracy():
    scene = SyntheticScene()
    rng = np.random.default_rng(1)
    tracker = BallTracker(TrackerConfig.from_values(), calibrated(scene.camera))
    for i in range(12):
        tracker.process(scene.render((0.0, 0.0))[0], i / FPS)
    rest, rolling = Score(), Score()
    t = 12
    for x, y in rng.uniform(-0.17, 0.17, (10, 2)):
        tracker.kalman.reset()
        for _ in range(10):
            rest.add(tracker.process(scene.render((x, y), noise_std=3.0, rng=rng)[0], t / FPS), x, y)
            t += 1
    pos, vel = circle_path(90, radius=0.15, revs=1.0)        # 0.31 m/s
    tracker.kalman.reset()
    for k, (p, v) in enumerate(zip(pos, vel)):
        r = tracker.process(scene.render(tuple(p), noise_std=3.0, rng=rng)[0], t / FPS)
        rolling.add(r, *p, *v, score_position=k >= 10)      # velocity needs a few frames
        t += 1
    return rest, rolling


def sim_accuracy():
    from ball_balance.sim.config import camera_intrinsics
    from ball_balance.sim.world import SimWorld

    world = SimWorld()
    cam = world.config.camera
    fx, fy, cx, cy = camera_intrinsics(cam)
    model = CameraModel(cam.width_px, cam.height_px, np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]]), np.zeros(5))
    tracker = BallTracker(TrackerConfig.from_values(), model)
    t0 = 0.0
    for i in range(12):
        tracker.process(world.render()[0], i / FPS)
    t0 = 12 / FPS
    rest, rolling, times = Score(), Score(), []
    rng = np.random.default_rng(2)
    for x, y in rng.uniform(-0.19, 0.19, (12, 2)):
        world.place_ball(x, y)
        tracker.kalman.reset()
        for _ in range(5):
            image, truth = world.render()
            r = tracker.process(image, t0)
            times.append(1e3 * r.timings_s["total"])
            rest.add(r, truth.ball.x, truth.ball.y)
            t0 += 1 / FPS
    for tilt in [(0.04, 0.03), (-0.03, 0.05), (0.05, -0.02), (-0.04, -0.04)]:
        q = list(robot.HOME_POSITIONS_RAD)
        q[3] += tilt[0]
        q[4] += tilt[1]
        world.set_joint_positions(list(robot.HOME_POSITIONS_RAD))
        world.place_ball(0.0, 0.0)
        world.set_joint_positions(q)
        world.place_ball(0.0, 0.0)
        tracker.kalman.reset()
        start = world.time_s
        for k in range(45):
            world.advance(1 / FPS)
            image, truth = world.render()
            b = truth.ball
            if not (b.on_plate and truth.visible) or max(abs(b.x), abs(b.y)) > 0.2:
                break
            r = tracker.process(image, t0 + world.time_s - start)
            times.append(1e3 * r.timings_s["total"])
            rolling.add(r, b.x, b.y, b.vx, b.vy, score_position=k >= 8)
        t0 += world.time_s - start + 1.0
    world.close()
    return rest, rolling, times


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timing-frames", type=int, default=600)
    parser.add_argument("--no-sim", action="store_true")
    args = parser.parse_args()
    cv2.setNumThreads(1)

    print(f"\n1. time per frame (ms), one core, {args.timing_frames} synthetic frames after start-up")
    print(f"{'stage':<12}" + "".join(f"{s:>16}" for s in STAGES))
    print(f"{'':<12}" + f"{'med':>9}{'p99':>7}" * len(STAGES))
    for width, height in [(640, 480), (960, 540)]:
        per_stage = timing(width, height, args.timing_frames)
        print(f"{f'{width}x{height}':<12}" + "".join(
            f"{pct(per_stage[s], 50):9.3f}{pct(per_stage[s], 99):7.3f}" for s in STAGES))

    print("\n2. accuracy against truth (filtered output; detection = ball_found / frames)")
    header = f"{'case':<28} {'RMSE mm':>8} {'max mm':>8} {'vel RMSE':>9} {'detect %':>8} {'frames':>7}"
    print(header)
    rest, rolling = synthetic_accuracy()
    print(rest.row("synthetic, at rest"))
    print(rolling.row("synthetic, rolling 0.31 m/s"))
    if not args.no_sim:
        try:
            sim_rest, sim_rolling, sim_times = sim_accuracy()
        except ImportError as error:
            print(f"(rendered frames skipped: {error})")
        else:
            print(sim_rest.row("rendered (MuJoCo), at rest"))
            print(sim_rolling.row("rendered (MuJoCo), rolling"))
            print(f"  rendered frames, total time per frame: median {pct(sim_times, 50):.3f} ms, "
                  f"p99 {pct(sim_times, 99):.3f} ms")


if __name__ == "__main__":
    main()
