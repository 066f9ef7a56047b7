"""Ball tracker benchmark: per-stage time, accuracy against truth, detection rate, latency.

1. Time per frame by stage (median, p99) at 640x480 and 960x540 on one core
   (cv2.setNumThreads(1)), synthetic frames of a rolling ball with sensor noise.
2. Position RMSE at rest and rolling, velocity RMSE, detection rate: synthetic frames
   (known camera) and, when ball_balance.sim is importable, MuJoCo-rendered frames with the
   simulation's truth (intrinsics as its /camera/camera_info gives them).
3. End-to-end latency: the ball_tracker executable as its own process on a private ROS
   domain; this process publishes 640x480 frames (reliable) stamped with the send time and
   receives /ball_state; latency = receipt time - frame stamp.

usage: python benchmarks/tracker_bench.py [--timing-frames 600] [--no-sim] [--no-latency]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from ball_balance import robot
from ball_balance.vision.camera import CameraModel
from ball_balance.vision.config import TrackerConfig
from ball_balance.vision.synthetic import SyntheticCamera, SyntheticScene
from ball_balance.vision.tracker import STAGES, BallTracker

ROOT = Path(__file__).resolve().parents[1]
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


# -- 3. latency ------------------------------------------------------------------------------
def latency(seconds=6.0):
    import rclpy
    from ball_tracker_msgs.msg import BallState
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, Image

    sys.path.insert(0, str(ROOT / "test"))
    from harness import DomainLease, executable, ros_env

    lease = DomainLease()
    env = ros_env(lease.domain_id)
    tracker = subprocess.Popen([executable("ball_tracker"), "--ros-args", "--params-file",
                                str(ROOT / "config" / "ball_tracker.yaml")], env=env,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    os.environ.update(ROS_DOMAIN_ID=str(lease.domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=lease.domain_id)
    node = rclpy.create_node("tracker_bench", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    scene = SyntheticScene()
    image = scene.render((0.05, 0.05), noise_std=2.0)[0]
    msg = Image(height=480, width=640, encoding="bgr8", step=640 * 3)
    msg.data = image.tobytes()
    info = CameraInfo(width=640, height=480, distortion_model="plumb_bob")
    info.k = [float(v) for v in scene.camera.K.ravel()]
    info.d = [0.0] * 5
    image_pub = node.create_publisher(Image, "/camera/image_raw", 10)
    info_pub = node.create_publisher(CameraInfo, "/camera/camera_info", qos_profile_sensor_data)
    latencies_ms, found = [], []

    def on_state(state):
        sent = state.header.stamp.sec * 1_000_000_000 + state.header.stamp.nanosec
        latencies_ms.append((time.time_ns() - sent) / 1e6)
        found.append(state.ball_found)

    node.create_subscription(BallState, "/ball_state", on_state, qos_profile_sensor_data)
    sent = [0]

    def tick():
        now = time.time_ns()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 1_000_000_000)
        image_pub.publish(msg)
        info_pub.publish(info)
        sent[0] += 1

    timer = node.create_timer(1 / FPS, tick)
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline and sum(found) < 5:      # discovery, QoS match, plate lock
        executor.spin_once(timeout_sec=0.05)
    latencies_ms.clear()
    sent[0] = 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
    node.destroy_timer(timer)
    received = len(latencies_ms)
    executor.shutdown()
    node.destroy_node()
    context.try_shutdown()
    os.killpg(tracker.pid, 2)
    tracker.wait(timeout=10)
    lease.release()
    return latencies_ms, sent[0], received


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timing-frames", type=int, default=600)
    parser.add_argument("--no-sim", action="store_true")
    parser.add_argument("--no-latency", action="store_true")
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

    if not args.no_latency:
        lat, sent, received = latency()
        print("\n3. end-to-end latency, image stamp -> /ball_state received in this process (640x480, 30 Hz, "
              "reliable images)")
        print(f"   median {pct(lat, 50):.2f} ms, p90 {pct(lat, 90):.2f} ms, p99 {pct(lat, 99):.2f} ms, "
              f"max {max(lat, default=float('nan')):.2f} ms; {received}/{sent} frames answered")


if __name__ == "__main__":
    main()
