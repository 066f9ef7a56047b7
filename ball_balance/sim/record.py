"""See the simulation without a display: a still PNG and/or a short MP4 of the overhead camera.

    python -m ball_balance.sim.record --png sim.png --mp4 sim.mp4 --duration 4

Runs SimWorld alone (no ROS): the ball starts at --ball-x/--ball-y and the plate rocks
gently (wrist_1/wrist_2 sinusoids of --tilt-deg amplitude) so the ball moves. Frames are
rendered at --fps of simulated time and written with cv2.VideoWriter (mp4v). To record
the running ROS camera instead, use the `camera_snapshot` executable.
"""
from __future__ import annotations

import argparse
import math
import sys
from typing import Optional, Sequence

import numpy as np

from ball_balance import robot
from ball_balance.sim.config import CameraConfig, DomainKnobs, SimConfig


def write_video(path: str, frames, fps: float) -> None:
    """Write BGR frames (iterable of H x W x 3 uint8) to an MP4 file."""
    import cv2

    writer = None
    try:
        for frame in frames:
            if writer is None:
                height, width = frame.shape[:2]
                writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"mp4v"), fps, (width, height))
                if not writer.isOpened():
                    raise OSError(f"cannot open {path} for writing (mp4v)")
            writer.write(frame)
    finally:
        if writer is not None:
            writer.release()


def rocking_frames(world, duration_s: float, fps: float, tilt_rad: float, period_s: float = 2.0):
    """Yield (image, truth) while the plate rocks about both axes."""
    home = np.array(robot.HOME_POSITIONS_RAD)
    frame_dt = 1.0 / fps
    for k in range(int(round(duration_s * fps))):
        t = k * frame_dt
        q = home.copy()
        q[3] += tilt_rad * math.sin(2 * math.pi * t / period_s)
        q[4] += tilt_rad * math.cos(2 * math.pi * t / period_s)
        world.set_joint_targets(q)
        world.advance(frame_dt)
        yield world.render()


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--png", help="write the first frame here")
    parser.add_argument("--mp4", help="write a video here")
    parser.add_argument("--duration", type=float, default=4.0, help="video length, simulated s")
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--ball-x", type=float, default=0.06)
    parser.add_argument("--ball-y", type=float, default=0.04)
    parser.add_argument("--tilt-deg", type=float, default=2.0)
    parser.add_argument("--antialias", type=int, default=4, help="MSAA samples (smoother stills)")
    parser.add_argument("--domain", default="standard")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    if not args.png and not args.mp4:
        parser.error("give --png and/or --mp4")
    import cv2

    from ball_balance.sim.config import SimConfigError
    from ball_balance.sim.world import SimWorld

    try:
        config = SimConfig(camera=CameraConfig(width_px=args.width, height_px=args.height, rate_hz=args.fps,
                                             antialias_samples=args.antialias))
        world = SimWorld(config, DomainKnobs.sample(args.domain, args.seed), seed=args.seed)
    except SimConfigError as error:
        print(f"record: {error}", file=sys.stderr)
        return 2
    world.place_ball(args.ball_x, args.ball_y)
    if args.png:
        image, truth = world.render()
        if not cv2.imwrite(args.png, image):
            print(f"record: cannot write {args.png}", file=sys.stderr)
            return 1
        print(f"{args.png}: {image.shape[1]}x{image.shape[0]}, ball at ({truth.ball.x:+.3f}, {truth.ball.y:+.3f}) m "
              f"= pixel ({truth.pixel_u:.1f}, {truth.pixel_v:.1f})")
    if args.mp4:
        frames = (image for image, _ in rocking_frames(world, args.duration, args.fps, math.radians(args.tilt_deg)))
        write_video(args.mp4, frames, args.fps)
        truth = world.ball_truth()
        print(f"{args.mp4}: {args.duration:.1f} s at {args.fps:g} fps; ball ends at ({truth.x:+.3f}, {truth.y:+.3f}) m"
              f"{' (dropped)' if truth.dropped else ''}")
    world.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
