"""One benchmark episode: SimWorld + (render + BallTracker | truth + noise + Kalman) + ControlPipeline,
advanced in lock-step on simulated time.

Timeline (simulated seconds): physics at 1 ms; the camera captures at `camera_rate_hz`;
a frame's tracker result becomes visible to the controller `vision_delay_s` after capture
(the tracker's processing time in the live graph); the controller ticks at its own rate
with the latest visible result, its age = tick time - capture time; joint commands reach
the arm after the domain's latency (SimWorld applies it). At t = 0 the arm is at home and
the ball is released at rest off-centre (radius 0.05-0.10 m, direction from the seed).
Metrics count from the controller's engagement (the ball rests on the level plate until
then, while the tracker starts up).

Modes: "vision" renders every frame and runs the real tracker (ArUco + HSV + Kalman);
"fast" feeds the tracker's Kalman filter with the true position plus Gaussian noise
(SimWorld.detected_ball: the domain's detection_noise_m, at least `fast_noise_floor_m`),
so sweeps are cheap; both produce BallState-equivalent observations. "truth" feeds the
true state itself (diagnostics: separates control from estimation).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Dict, Optional

import numpy as np

from ball_balance.control import config as control_config
from ball_balance.control.kinematics import Chain, PlateKinematics
from ball_balance.control.pipeline import ControlPipeline
from ball_balance.control.safety import BallObservation, Mode
from ball_balance.robot import HOME_POSITIONS_RAD, JOINT_NAMES, robot_description
from controller_manager_py.parameters import validate

REFERENCES = {
    "stationary": dict(reference_kind="stationary"),
    "circle": dict(reference_kind="circle", reference_radius_m=0.10, reference_period_s=10.0),
    "figure_eight": dict(reference_kind="figure_eight", reference_radius_m=0.10, reference_period_s=12.0),
}


@dataclass(frozen=True)
class EpisodeSpec:
    controller: str = "pid"                 # pid | mpc
    domain: str = "standard"                # DOMAINS of ball_balance.sim.config
    reference: str = "stationary"           # key of REFERENCES
    seed: int = 0
    duration_s: float = 20.0
    mode: str = "fast"                      # fast | vision
    camera_rate_hz: float = 30.0
    vision_delay_s: float = 0.015
    fast_noise_floor_m: float = 0.0005      # pixel quantisation of the real tracker, roughly
    release_radius_m: tuple = (0.05, 0.10)
    overrides: tuple = ()                   # extra controller parameters ((name, value), ...)
    record: bool = False                    # keep time series (for plots)


@dataclass
class EpisodeResult:
    spec: EpisodeSpec
    metrics: Dict[str, float]
    series: Optional[Dict[str, np.ndarray]] = None
    frames: list = field(default_factory=list)   # (image, overlay info) when asked for video


_CHAIN_CACHE = {}


def _kinematics(values) -> PlateKinematics:
    if "chain" not in _CHAIN_CACHE:
        _CHAIN_CACHE["chain"] = Chain.from_urdf(robot_description(), JOINT_NAMES)
    return control_config.plate_kinematics(_CHAIN_CACHE["chain"], values)


def controller_values(controller: str, reference: str, overrides=()) -> dict:
    """Validated controller parameters: schema defaults + config/<pid|mpc>.yaml + overrides."""
    from pathlib import Path

    import yaml

    schema = control_config.PID_SCHEMA if controller == "pid" else control_config.MPC_NODE_SCHEMA
    node = "ball_balance_controller" if controller == "pid" else "ball_balance_mpc"
    path = Path(__file__).resolve().parents[2] / "config" / f"{controller}.yaml"
    values = {}
    if path.exists():
        values = yaml.safe_load(path.read_text())[node]["ros__parameters"]
    values.update(REFERENCES[reference])
    values.update(dict(overrides))
    return dict(validate(schema, values, allow_unknown=True))


def tracker_values() -> dict:
    """The tracker parameters the graph runs with (config/ball_tracker.yaml), for both modes."""
    from pathlib import Path

    import yaml

    path = Path(__file__).resolve().parents[2] / "config" / "ball_tracker.yaml"
    if not path.exists():
        return {}
    return dict(yaml.safe_load(path.read_text())["ball_tracker"]["ros__parameters"])


def run_episode(spec: EpisodeSpec, video_every: int = 0) -> EpisodeResult:
    from ball_balance.sim.config import DomainKnobs, SimConfig, camera_intrinsics
    from ball_balance.sim.world import SimWorld
    from ball_balance.vision.camera import CameraModel
    from ball_balance.vision.config import TrackerConfig
    from ball_balance.vision.kalman import BallKalman
    from ball_balance.vision.tracker import BallTracker

    values = controller_values(spec.controller, spec.reference, spec.overrides)
    knobs = DomainKnobs.sample(spec.domain, spec.seed)
    world = SimWorld(SimConfig(), knobs, urdf_text=robot_description(), seed=spec.seed)
    rng = np.random.default_rng(spec.seed + 7919)
    radius = rng.uniform(*spec.release_radius_m)
    angle = rng.uniform(0, 2 * math.pi)
    world.reset(HOME_POSITIONS_RAD, (radius * math.cos(angle), radius * math.sin(angle)))

    pipeline = ControlPipeline(control_config.pipeline_config(values, spec.controller), _kinematics(values),
                               control_config.reference(values))
    tracker_cfg = TrackerConfig.from_values(tracker_values())
    tracker = None
    if spec.mode == "vision":  # the rendered camera's intrinsics, as /camera/camera_info gives them
        camera = world.config.camera
        tracker = BallTracker(tracker_cfg, CameraModel.pinhole(camera.width_px, camera.height_px,
                                                               *camera_intrinsics(camera)))
    kalman = None
    if spec.mode == "fast":
        noise = max(knobs.detection_noise_m, spec.fast_noise_floor_m)
        kalman = BallKalman(max(tracker_cfg.meas_noise_m, noise), tracker_cfg.accel_noise_m_s2,
                            tracker_cfg.init_vel_std_m_s, tracker_cfg.gate_sigma, tracker_cfg.max_coast_frames,
                            tracker_cfg.max_dt_s)
        world.knobs = knobs if knobs.detection_noise_m >= spec.fast_noise_floor_m else \
            _with_noise(knobs, spec.fast_noise_floor_m)

    control_dt = 1.0 / values["control_rate_hz"]
    frame_dt = 1.0 / spec.camera_rate_hz
    steps_per_tick = int(round(control_dt / world.physics_dt_s))
    pending = []            # (visible_at_s, observation fields, capture_s)
    latest = None           # (obs fields tuple, capture_s)
    next_frame_s = 0.0
    kg = values["rolling_factor"] * values["gravity_m_s2"]
    rec = {k: [] for k in ("t", "x", "y", "rx", "ry", "ux", "uy", "age", "mode", "ex", "ey")}
    frames = []
    solve_times = []        # whole control tick (wall time)
    qp_times = []           # MPC solve alone
    u_cmd = (0.0, 0.0)
    n_ticks = int(round(spec.duration_s / control_dt))
    for tick in range(n_ticks):
        t = world.time_s
        # camera frames captured up to now
        while next_frame_s <= t + 1e-9:
            if spec.mode == "vision":
                image, truth = world.render()
                tracker.set_plate_cmd(u_cmd[0], u_cmd[1], t)
                r = tracker.process(image, t)
                fields_ = (r.x, r.y, r.vx, r.vy, r.tracking_valid, r.markers_found)
                if video_every and len(frames) < 10000 and tick % video_every == 0:
                    frames.append((image, r))
            elif spec.mode == "truth":
                tr = world.ball_truth()
                fields_ = (tr.x, tr.y, tr.vx, tr.vy, True, 4)
            else:
                zx, zy = world.detected_ball()
                accel = (-kg * math.sin(u_cmd[0]), -kg * math.sin(u_cmd[1])) if tracker_cfg.use_plate_cmd else None
                est = kalman.step(t, (zx, zy), accel)
                fields_ = (est.x, est.y, est.vx, est.vy, est.valid, 4)
            pending.append((t + spec.vision_delay_s, fields_, t))
            next_frame_s += frame_dt
        while pending and pending[0][0] <= t + 1e-9:
            _, fields_, capture = pending.pop(0)
            latest = (fields_, capture)
        obs = None
        if latest is not None:
            (x, y, vx, vy, valid, markers), capture = latest
            obs = BallObservation(x, y, vx, vy, valid, markers, t - capture)
        t0 = time.perf_counter()
        result = pipeline.step(t, obs, world.joint_positions())
        solve_times.append(time.perf_counter() - t0)
        if pipeline.mpc is not None and result.mode == Mode.ENGAGED:
            qp_times.append(pipeline.mpc.last_solve_s)
        u_cmd = result.u
        world.set_joint_targets(result.q_cmd)
        world.step(steps_per_tick)
        truth = world.ball_truth()
        ref = result.ref.p if result.ref is not None else pipeline.reference.sample(0.0).p
        rec["t"].append(t)
        rec["x"].append(truth.x)
        rec["y"].append(truth.y)
        rec["rx"].append(ref[0])
        rec["ry"].append(ref[1])
        rec["ux"].append(u_cmd[0])
        rec["uy"].append(u_cmd[1])
        rec["age"].append(obs.age_s if obs is not None else math.nan)
        rec["mode"].append(result.mode == Mode.ENGAGED)
        rec["ex"].append(obs.x if obs is not None else math.nan)
        rec["ey"].append(obs.y if obs is not None else math.nan)
        if world.ball_dropped:
            break
    series = {k: np.asarray(v, dtype=float) for k, v in rec.items()}
    # count from the controller's engagement (until then the ball rests on the level plate
    # while the tracker starts up), as the live recorder does
    engaged = np.nonzero(series["mode"] > 0)[0]
    first = int(engaged[0]) if len(engaged) else 0
    series = {k: v[first:] for k, v in series.items()}
    series["t"] = series["t"] - (series["t"][0] if len(series["t"]) else 0.0)
    from ball_balance.benchmark.metrics import episode_metrics

    metrics = episode_metrics(series, dropped=world.ball_dropped, duration_s=spec.duration_s,
                              actuation_latency_s=knobs.latency_s)
    metrics["tick_p50_us"] = float(np.percentile(solve_times, 50) * 1e6)
    metrics["tick_p99_us"] = float(np.percentile(solve_times, 99) * 1e6)
    if qp_times:
        metrics["qp_p50_us"] = float(np.percentile(qp_times, 50) * 1e6)
        metrics["qp_p99_us"] = float(np.percentile(qp_times, 99) * 1e6)
    metrics["delay_estimate_s"] = pipeline.actuation_delay_s
    metrics["qp_fallbacks"] = float(pipeline.mpc.failures if pipeline.mpc is not None else 0)
    world.close()
    return EpisodeResult(spec, metrics, series if spec.record else None, frames)


def _with_noise(knobs, noise_m):
    from dataclasses import replace

    return replace(knobs, detection_noise_m=noise_m)
