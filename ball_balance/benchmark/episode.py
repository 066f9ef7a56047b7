"""One benchmark episode: SimWorld + (render + BallTracker | truth + noise + Kalman) + ControlPipeline,
advanced in lock-step on simulated time. Everything an episode does is in its EpisodeSpec:
controller, domain, reference, release (position and rolling speed), ball type, knob
overrides and timed events (pushes, external forces, a hand over markers, exposure changes,
camera outages), so a new case never needs a copy of the loop. The domain adds its own
(`episode_events`): pushes, hands, and force steps (on at 5 s, turned at 9 s, off at 13 s).

Timeline (simulated seconds): physics at 1 ms; the camera captures at `camera_rate_hz`
(a frame may be dropped, `frame_drop_prob`, and its stamp may be off the true capture time,
`stamp_jitter_s`); a frame's tracker result becomes visible to the controller
`vision_delay_s` after capture (the tracker's processing time in the live graph); the
controller ticks at its own rate with the latest visible result, its age = tick time -
frame stamp; joint commands reach the arm after the domain's latency (SimWorld applies it).
At t = 0 the arm is at home and the ball is released off-centre (radius and rolling speed
from `release_radius_m` and `release_speed_m_s`, directions from the seed). Events act at
the first control tick at or after their time `t_s` (simulated seconds since the release).
Metrics count from the controller's engagement (the ball rests on the level plate until
then, while the tracker starts up); after that, time the controller is not engaged counts
as error against the reference the user asked for.

Modes: "vision" renders every frame (with the camera model: exposure gain, sensor noise of
at least `vision_noise_floor`, motion blur over `blur_exposure_s`, hands over markers)
and runs the real tracker (ArUco + HSV + Kalman); "fast" feeds the tracker's Kalman
filter with the true position plus Gaussian noise (SimWorld.detected_ball: the domain's
detection_noise_m, at least `fast_noise_floor_m`), so sweeps are cheap; both produce
BallState-equivalent observations.
"truth" feeds the true state itself (diagnostics: separates control from estimation).
"""
from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Dict, Optional, Tuple

import numpy as np

from ball_balance.config_values import (  # noqa: F401 (the benchmark's public names)
    CONFIG_DIR,
    REFERENCES,
    controller_schema,
    controller_values,
    tracker_values,
)
from ball_balance.control import config as control_config
from ball_balance.control.kinematics import Chain, PlateKinematics
from ball_balance.control.pipeline import ControlPipeline
from ball_balance.control.safety import BallObservation, Mode
from ball_balance.robot import HOME_POSITIONS_RAD, JOINT_NAMES, robot_description
from ball_balance.sim.config import CAMERA_RATE_HZ, FAST_NOISE_FLOOR_M, VISION_DELAY_S
from controller_manager_py.controllers.command_ramp import CommandRamp

BALLS = {"": None, "shell": True, "solid": False}   # EpisodeSpec.ball -> DomainKnobs.ball_shell


# ---- events (all times in simulated seconds since the release) ---------------------------
@dataclass(frozen=True)
class Push:
    """An impulse: the ball's velocity changes by (dvx, dvy) m/s, plate axes, spin kept rolling."""

    t_s: float
    dvx: float
    dvy: float


@dataclass(frozen=True)
class Force:
    """An external force (N, plate axes) on the ball's centre from t_s for duration_s.

    A pulse (`step` False) counts as a push in the recovery figures; a held load (`step`
    True) has its start and its end counted as steps (step_recover_*, step_steady_m)."""

    t_s: float
    duration_s: float
    fx_n: float
    fy_n: float
    step: bool = False


@dataclass(frozen=True)
class Occlusion:
    """A hand over the given markers (ids 0-3) from t_s for duration_s. Vision mode paints it
    into the frames; fast mode reports that many fewer markers."""

    t_s: float
    duration_s: float
    markers: Tuple[int, ...] = (0, 1)


@dataclass(frozen=True)
class Exposure:
    """From t_s on, the camera's image gain is `gain` (vision mode), e.g. auto-exposure stepping."""

    t_s: float
    gain: float


@dataclass(frozen=True)
class CameraGap:
    """No camera frame arrives from t_s for duration_s (a cable glitch, a driver restart)."""

    t_s: float
    duration_s: float


@dataclass(frozen=True)
class EpisodeSpec:
    controller: str = "pid"                 # any controller the pipeline knows (pid, mpc, ...)
    domain: str = "standard"                # DOMAINS (or DOMAIN_ALIASES) of ball_balance.sim.config
    reference: str = "stationary"           # key of REFERENCES
    seed: int = 0
    duration_s: float = 20.0
    mode: str = "fast"                      # fast | vision | truth
    camera_rate_hz: float = CAMERA_RATE_HZ
    vision_delay_s: float = VISION_DELAY_S
    fast_noise_floor_m: float = FAST_NOISE_FLOOR_M
    vision_noise_floor: float = 2.0         # sensor noise of a real camera, grey levels (vision mode)
    release_radius_m: tuple = (0.05, 0.10)
    release_xy_m: tuple = ()                # (x, y): released there instead (release_radius_m unused)
    release_speed_m_s: tuple = (0.0, 0.0)   # rolling speed at release, seeded direction
    ball: str = ""                          # "" (the domain's), "shell" or "solid"
    knobs: tuple = ()                       # DomainKnobs overrides ((name, value), ...)
    events: tuple = ()                      # Push, Force, Occlusion, Exposure, CameraGap
    protocol: str = "ours"                  # label of the protocol the spec follows (table rows)
    overrides: tuple = ()                   # extra controller parameters ((name, value), ...)
    tracker_overrides: tuple = ()           # tracker parameters over config/ball_tracker.yaml ((name, value), ...)
    # How the joint targets reach the arm: > 0, ramped over each control period and written at
    # this rate, as BallBalanceController does in the manager and the simulated arm's
    # forward_position_controller does with the balance nodes' targets (command_ramp, at the
    # update rate of config/ur_controllers.yaml); 0, one step per control tick, as a forward
    # controller without the ramp writes them.
    command_write_hz: float = 500.0
    record: bool = False                    # keep time series (for plots)


def release_point(spec: EpisodeSpec, rng) -> tuple:
    """Where the ball is released (plate frame, m): `release_xy_m`, else a seeded point at a
    radius in `release_radius_m` (drawn from `rng` either way, so later draws do not change)."""
    radius = rng.uniform(*spec.release_radius_m)
    angle = rng.uniform(0, 2 * math.pi)
    if spec.release_xy_m:
        return tuple(spec.release_xy_m)
    return radius * math.cos(angle), radius * math.sin(angle)


DEMO_START_DELAY_S = 6.0


def demo_spec(controller: str, domain: str = "standard", seed: int = 0, duration_s: float = 30.0) -> EpisodeSpec:
    """The scenario of scripts/run_demo.sh, lock-stepped: the ball released at rest at
    (0.08, -0.05) m, balanced at the centre, then a circle r = 0.10 m, T = 10 s from 6 s on;
    the rendered camera at 60 Hz (config/sim.yaml) and the full tracker, each frame answered
    one frame period after its capture, as the lock-stepped graph guarantees at the latest."""
    return EpisodeSpec(controller=controller, domain=domain, reference="circle", seed=seed, duration_s=duration_s,
                       mode="vision", camera_rate_hz=60.0, vision_delay_s=1.0 / 60.0, release_xy_m=(0.08, -0.05),
                       overrides=(("reference_start_delay_s", DEMO_START_DELAY_S),), protocol="demo")


def reference_protocol(spec: EpisodeSpec) -> EpisodeSpec:
    """The reference system's protocol for the same cell: released 0-2 cm off centre at rest,
    600 steps at 30 Hz (20 s); its RMSE (`rmse_release_m`) is over the steps before a drop."""
    return dataclasses.replace(spec, release_radius_m=(0.0, 0.02), release_speed_m_s=(0.0, 0.0),
                               duration_s=20.0, camera_rate_hz=30.0, protocol="reference")


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


def episode_knobs(spec: EpisodeSpec):
    """The domain's knobs for this seed with the spec's ball type and knob overrides applied."""
    from ball_balance.sim.config import DomainKnobs, SimConfigError

    knobs = DomainKnobs.sample(spec.domain, spec.seed)
    if spec.ball not in BALLS:
        raise SimConfigError(f"ball = {spec.ball!r} must be one of {sorted(BALLS)}")
    if spec.ball:
        knobs = dataclasses.replace(knobs, ball_shell=BALLS[spec.ball])
    names = {f.name for f in dataclasses.fields(knobs)}
    unknown = [name for name, _ in spec.knobs if name not in names]
    if unknown:
        raise SimConfigError(f"unknown knob(s) {unknown}: expected some of {sorted(names)}")
    return dataclasses.replace(knobs, **dict(spec.knobs))


def episode_events(spec: EpisodeSpec, knobs) -> list:
    """The spec's events plus the domain's pushes (seeded directions), hands over markers
    (seeded markers) and force steps (DomainKnobs.force_steps, held Force events) that start
    before the episode's end, in time order."""
    events = list(spec.events)
    events += [Force(*step, step=True) for step in knobs.force_steps() if step[0] < spec.duration_s]
    if knobs.occlusion_markers > 0:
        rng = np.random.default_rng(spec.seed + 1299709)
        t = knobs.occlusion_interval_s
        while t < spec.duration_s:
            markers = tuple(sorted(int(m) for m in rng.choice(4, knobs.occlusion_markers, replace=False)))
            events.append(Occlusion(t, knobs.occlusion_duration_s, markers))
            t += knobs.occlusion_interval_s
    if knobs.push_speed_m_s > 0.0:
        rng = np.random.default_rng(spec.seed + 104729)
        t = knobs.push_interval_s
        while t < spec.duration_s:
            angle = rng.uniform(0.0, 2.0 * math.pi)
            events.append(Push(t, knobs.push_speed_m_s * math.cos(angle), knobs.push_speed_m_s * math.sin(angle)))
            t += knobs.push_interval_s
    return sorted(events, key=lambda e: e.t_s)


def step_times(times, tolerance_s: float) -> list:
    """The distinct step times among the held forces' starts and ends: one force ending as
    the next starts is one step (a change), not two."""
    out = []
    for t in sorted(times):
        if not out or t - out[-1] > tolerance_s:
            out.append(t)
    return out


def _observation(x, y, vx, vy, valid, markers, age_s, position_std_m, level_offset_rad=None):
    """BallObservation, with the tracker's position uncertainty and level offset where the type
    carries them."""
    extra = {}
    if "position_std_m" in _OBSERVATION_FIELDS:
        extra["position_std_m"] = position_std_m
    if "level_offset_rad" in _OBSERVATION_FIELDS:
        extra["level_offset_rad"] = level_offset_rad
    return BallObservation(x, y, vx, vy, valid, markers, age_s, **extra)


_OBSERVATION_FIELDS = {f.name for f in dataclasses.fields(BallObservation)}
_COVARIANCE_CACHE: Dict[tuple, Optional[np.ndarray]] = {}


def fast_pose_covariance(visible: Tuple[int, ...], camera, corner_noise_px: float) -> Optional[np.ndarray]:
    """The covariance (6x6, ball_balance.vision.pose_quality) of the plate pose the tracker
    would fit to the `visible` markers' corners at the nominal overhead pose (the 1-2 marker
    fit with its pivot prior); None without markers."""
    key = (visible, camera, corner_noise_px)
    if key not in _COVARIANCE_CACHE:
        from ball_balance.plate_geometry import PlateGeometry
        from ball_balance.sim.config import camera_intrinsics
        from ball_balance.vision import pose_quality, tracker
        from ball_balance.vision.plate import FULL_FIT_MIN_MARKERS

        covariance = None
        if visible:
            geometry = PlateGeometry()
            fx, fy, cx, cy = camera_intrinsics(camera)
            K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
            points = np.concatenate([np.array(geometry.marker_corners_m(m)) for m in visible])
            prior = tracker.PRIOR_INFORMATION if len(visible) < FULL_FIT_MIN_MARKERS else None
            covariance = pose_quality.pose_covariance(points, K, pose_quality.R_CP_OVERHEAD,
                                                      np.array([0.0, 0.0, camera.height_above_plate_m]),
                                                      corner_noise_px, prior)
        _COVARIANCE_CACHE[key] = covariance
    return _COVARIANCE_CACHE[key]


def fast_position_std_m(visible: Tuple[int, ...], camera, corner_noise_px: float) -> float:
    """Fast mode's stand-in for the tracker's position_std_m: the ball-position error the
    plate pose fitted to the `visible` markers' corners would cause (the tracker's own model,
    ball_balance.vision.pose_quality), so the controllers judge a hand over markers as in
    vision mode."""
    from ball_balance.vision import pose_quality

    covariance = fast_pose_covariance(visible, camera, corner_noise_px)
    if covariance is None:
        return math.inf
    return pose_quality.ball_position_std_m(covariance, camera.height_above_plate_m)


def fast_tilt_std_rad(visible: Tuple[int, ...], camera, corner_noise_px: float) -> float:
    """Fast mode's noise of the plate tilt the tracker measures from its pose fit (1 sigma per
    axis, rad: the fit's rotation about the camera's x and y axes); inf without markers."""
    covariance = fast_pose_covariance(visible, camera, corner_noise_px)
    if covariance is None:
        return math.inf
    return float(np.sqrt(0.5 * (covariance[3, 3] + covariance[4, 4])))


def run_episode(spec: EpisodeSpec, video_every: int = 0) -> EpisodeResult:
    from ball_balance.sim.camera import develop, hand_over_markers
    from ball_balance.sim.config import SimConfig, camera_intrinsics
    from ball_balance.sim.world import SimWorld
    from ball_balance.vision.camera import CameraModel
    from ball_balance.vision.config import TrackerConfig
    from ball_balance.vision.kalman import (
        BallKalman,
        CommandDelayFromTilt,
        KalmanConfig,
        PlateCommandInput,
        plate_tilt_rad,
    )
    from ball_balance.vision.tracker import BallTracker

    values = controller_values(spec.controller, spec.reference, spec.overrides)
    knobs = episode_knobs(spec)
    events = episode_events(spec, knobs)
    world = SimWorld(SimConfig(), knobs, urdf_text=robot_description(), seed=spec.seed)
    rng = np.random.default_rng(spec.seed + 7919)
    world.reset(HOME_POSITIONS_RAD, release_point(spec, rng))
    if spec.release_speed_m_s[1] > 0.0:
        speed, heading = rng.uniform(*spec.release_speed_m_s), rng.uniform(0, 2 * math.pi)
        world.push_ball(speed * math.cos(heading), speed * math.sin(heading))
    camera_rng = np.random.default_rng(spec.seed + 15485863)   # drops, stamp jitter, sensor noise

    pipeline = ControlPipeline(control_config.pipeline_config(values, spec.controller), _kinematics(values),
                               control_config.reference(values))
    tracker_cfg = TrackerConfig.from_values({**tracker_values(), **dict(spec.tracker_overrides)})
    tracker = None
    if spec.mode == "vision":  # the rendered camera's intrinsics, as /camera/camera_info gives them
        camera = world.config.camera
        tracker = BallTracker(tracker_cfg, CameraModel.pinhole(camera.width_px, camera.height_px,
                                                               *camera_intrinsics(camera)))
        world.history_s = knobs.blur_exposure_s
    kalman = None
    if spec.mode == "fast":
        # the tracker's own filter; a fixed measurement noise stands in for one tuned to this
        # domain's noise, an adaptive one starts from the configured value as the live tracker does
        noise = max(knobs.detection_noise_m, spec.fast_noise_floor_m)
        kalman_cfg = KalmanConfig.from_tracker(tracker_cfg)
        if not kalman_cfg.adaptive_meas_noise:
            kalman_cfg = dataclasses.replace(kalman_cfg, meas_noise_m=max(kalman_cfg.meas_noise_m, noise))
        kalman = BallKalman(kalman_cfg)
        plate_cmds = PlateCommandInput(values["rolling_factor"] * values["gravity_m_s2"],
                                       tracker_cfg.plate_cmd_delay_s, tracker_cfg.plate_cmd_timeout_s,
                                       lever_m=tracker_cfg.tilt_lever_m)
        # the tracker's delay estimate, fed the plate's true tilt (from the level home pose) plus
        # the noise its pose fit would have
        plate_delay = CommandDelayFromTilt.from_config(tracker_cfg, plate_cmds) \
            if tracker_cfg.estimate_plate_cmd_delay and tracker_cfg.use_plate_cmd else None
        R_home = world.plate_pose()[1]
        tilt_rng = np.random.default_rng(spec.seed + 32452843)   # its own: the camera's draws stay as they were
        world.knobs = knobs if knobs.detection_noise_m >= spec.fast_noise_floor_m else \
            dataclasses.replace(knobs, detection_noise_m=spec.fast_noise_floor_m)

    control_dt = 1.0 / values["control_rate_hz"]
    frame_dt = 1.0 / spec.camera_rate_hz
    steps_per_tick = int(round(control_dt / world.physics_dt_s))
    ramp = None
    if spec.command_write_hz > 0.0:
        steps_per_write = max(1, int(round(1.0 / (spec.command_write_hz * world.physics_dt_s))))
        write_dt = steps_per_write * world.physics_dt_s
        ramp, written = CommandRamp(len(JOINT_NAMES)), None
    pending = []            # (visible_at_s, observation fields, stamp_s)
    latest = None           # (obs fields tuple, stamp_s)
    next_frame_s = 0.0
    rec = {k: [] for k in ("t", "x", "y", "rx", "ry", "ux", "uy", "age", "mode", "ex", "ey", "markers")}
    frames = []
    solve_times = []        # whole control tick (wall time)
    qp_times = []           # MPC solve alone
    u_cmd = (0.0, 0.0)
    gain = knobs.exposure
    pushes = []             # times of the pushes and force pulses (push recovery)
    steps = []              # starts and ends of the held forces (step recovery)
    upcoming = list(events)
    active = []             # Occlusion / CameraGap events in force
    n_ticks = int(round(spec.duration_s / control_dt))
    for tick in range(n_ticks):
        t = world.time_s
        while upcoming and upcoming[0].t_s <= t + 1e-9:
            event = upcoming.pop(0)
            if isinstance(event, Push):
                world.push_ball(event.dvx, event.dvy)
                pushes.append(t)
            elif isinstance(event, Force):
                world.apply_force(event.fx_n, event.fy_n, event.duration_s)
                if event.step:
                    steps += [t, t + event.duration_s]
                else:
                    pushes.append(t)
            elif isinstance(event, Exposure):
                gain = event.gain
            elif isinstance(event, (Occlusion, CameraGap)):
                active.append(event)
            else:
                raise TypeError(f"unknown episode event {event!r}")
        active = [e for e in active if t < e.t_s + e.duration_s - 1e-9]
        hidden = sorted({m for e in active if isinstance(e, Occlusion) for m in e.markers})
        # camera frames captured up to now
        while next_frame_s <= t + 1e-9:
            next_frame_s += frame_dt
            if any(isinstance(e, CameraGap) for e in active) or \
                    (knobs.frame_drop_prob > 0.0 and camera_rng.random() < knobs.frame_drop_prob):
                continue
            stamp = t + (camera_rng.normal(0.0, knobs.stamp_jitter_s) if knobs.stamp_jitter_s > 0.0 else 0.0)
            if spec.mode == "vision":
                noise = max(knobs.sensor_noise, spec.vision_noise_floor)
                image = develop(world.render_exposure(knobs.blur_exposure_s), gain, noise, camera_rng)
                if hidden:
                    image = hand_over_markers(image, world, hidden)
                r = tracker.process(image, stamp)
                fields_ = (r.x, r.y, r.vx, r.vy, r.tracking_valid, r.markers_found,
                           float(getattr(r, "position_std_m", 0.0)), getattr(r, "level_offset_rad", None))
                if video_every and len(frames) < 10000 and tick % video_every == 0:
                    frames.append((image, r))
            elif spec.mode == "truth":
                tr = world.ball_truth()
                fields_ = (tr.x, tr.y, tr.vx, tr.vy, True, 4 - len(hidden), 0.0, None)
            else:
                zx, zy = world.detected_ball()
                visible = tuple(m for m in range(4) if m not in hidden)
                if plate_delay is not None and visible:
                    tilt_std = fast_tilt_std_rad(visible, world.config.camera, tracker_cfg.corner_noise_px)
                    tilt = np.asarray(plate_tilt_rad(R_home, world.plate_pose()[1]))
                    plate_delay.add_tilt(stamp, tilt + tilt_rng.normal(0.0, tilt_std, 2))
                accel = lever = None
                if tracker_cfg.use_plate_cmd:
                    accel, lever = plate_cmds.inputs(stamp)
                est = kalman.step(stamp, (zx, zy), accel, lever)
                std = fast_position_std_m(visible, world.config.camera, tracker_cfg.corner_noise_px)
                level = kalman.level_offset_rad(plate_cmds.k_g) if kalman.disturbance_state else None
                fields_ = (est.x, est.y, est.vx, est.vy, est.valid, len(visible), std, level)
            pending.append((t + spec.vision_delay_s, fields_, stamp))
        while pending and pending[0][0] <= t + 1e-9:
            _, fields_, stamp = pending.pop(0)
            latest = (fields_, stamp)
        obs = None
        if latest is not None:
            (x, y, vx, vy, valid, markers, std, level), stamp = latest
            obs = _observation(x, y, vx, vy, valid, markers, t - stamp, std, level)
        t0 = time.perf_counter()
        result = pipeline.step(t, obs, world.joint_positions())
        solve_times.append(time.perf_counter() - t0)
        if pipeline.mpc is not None and result.mode == Mode.ENGAGED:
            qp_times.append(pipeline.mpc.last_solve_s)
        u_cmd = result.u
        # /plate_cmd as the tracker receives it
        if tracker is not None:
            tracker.set_plate_cmd(*result.plate_cmd, t)
        elif kalman is not None:
            plate_cmds.add(*result.plate_cmd, t)
        if ramp is None:
            world.set_joint_targets(result.q_cmd)
            world.step(steps_per_tick)
        else:  # as the controller's updates write it (the first write of a step already moves)
            ramp.start(result.q_cmd if written is None else written, result.q_cmd, t - write_dt, control_dt)
            for first in range(0, steps_per_tick, steps_per_write):
                written = ramp.at(t + first * world.physics_dt_s)
                world.set_joint_targets(written)
                world.step(min(steps_per_write, steps_per_tick - first))
        truth = world.ball_truth()
        # the reference the user asked for at the truth's instant, on the clock of the last
        # engagement (no latency look-ahead; it keeps running while the controller is not engaged)
        ref = pipeline.reference.sample(truth.time_s - pipeline.t_engaged).p
        rec["t"].append(truth.time_s)
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
        rec["markers"].append(obs.markers_found if obs is not None else math.nan)
        if world.ball_dropped:
            break
    series = {k: np.asarray(v, dtype=float) for k, v in rec.items()}
    from ball_balance.benchmark.metrics import episode_metrics, release_rmse

    rmse_release = release_rmse(series, rate_hz=30.0)
    # count from the controller's engagement (until then the ball rests on the level plate
    # while the tracker starts up), as the live recorder does
    engaged = np.nonzero(series["mode"] > 0)[0]
    first = int(engaged[0]) if len(engaged) else 0
    t_first = series["t"][first] if len(series["t"]) else 0.0
    series = {k: v[first:] for k, v in series.items()}
    series["t"] = series["t"] - t_first
    metrics = episode_metrics(series, dropped=world.ball_dropped, duration_s=spec.duration_s,
                              actuation_latency_s=knobs.latency_s,
                              push_times_s=[tp - t_first for tp in pushes if tp >= t_first],
                              step_times_s=[ts - t_first for ts in step_times(steps, control_dt / 2.0)
                                            if t_first <= ts < spec.duration_s - control_dt / 2.0])
    metrics["rmse_release_m"] = rmse_release
    metrics["tick_p50_us"] = float(np.percentile(solve_times, 50) * 1e6)
    metrics["tick_p99_us"] = float(np.percentile(solve_times, 99) * 1e6)
    if qp_times:
        metrics["qp_p50_us"] = float(np.percentile(qp_times, 50) * 1e6)
        metrics["qp_p99_us"] = float(np.percentile(qp_times, 99) * 1e6)
    metrics["delay_estimate_s"] = pipeline.actuation_delay_s
    # the delay the tracker's filter used at the end (its estimate, or plate_cmd_delay_s)
    if tracker is not None:
        metrics["tracker_delay_s"] = tracker.plate_cmds.delay_s
    elif kalman is not None:
        metrics["tracker_delay_s"] = plate_cmds.delay_s
    metrics["qp_fallbacks"] = float(pipeline.mpc.failures if pipeline.mpc is not None else 0)
    world.close()
    return EpisodeResult(spec, metrics, series if spec.record else None, frames)
