"""SimWorld: the UR arm, plate, ball and overhead camera in MuJoCo, as plain Python (no ROS).

    world = SimWorld()                      # home pose, ball at rest on the plate centre
    world.set_joint_targets(q)              # 6 joint positions (rad), JOINT_NAMES order
    world.advance(0.5)                      # step physics for 0.5 s of simulated time
    world.joint_positions(), world.ball_truth(), world.ball_dropped
    image_bgr, truth = world.render()       # overhead camera frame + what is really there

Joint servos: each joint follows its target through a slew limit (the URDF velocity limit
x speed scaling) and a critically damped position servo with `SimConfig.servo_lag_s` time
constant, torque-limited to the URDF effort; the arm's gravity is compensated (as the UR
controller does). Commands are applied `DomainKnobs.latency_s` after they are given.

`render()` makes test frames with known truth for the tracker: place the ball with
`place_ball(x, y)` and the arm with `set_joint_positions(q)`, then `render()` returns
(H x W x 3 uint8 BGR image, FrameTruth with the ball in the plate frame and in pixels).
It renders in the calling thread; the ROS component uses `snapshot()` + CameraRenderer in
its own thread instead.
"""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass
from typing import Optional, Sequence, Tuple

import mujoco
import numpy as np

from ball_balance import robot
from ball_balance.plate_geometry import PLATE_SIDE_M, PLATE_THICKNESS_M
from ball_balance.sim.config import DomainKnobs, SimConfig, camera_intrinsics
from ball_balance.sim.model import build_model


class CommandError(ValueError):
    """A joint command was refused (non-finite, wrong length, outside the joint limits)."""


class SimulationError(RuntimeError):
    """The physics diverged (MuJoCo reset its state); the world was reset to the last targets."""


@dataclass(frozen=True)
class BallTruth:
    """The ball's true state in the plate frame (metres, m/s) at `time_s` (sim seconds).

    z is the ball centre's height above the plate centre plane (about thickness/2 + radius
    when resting on the plate). vx, vy are velocities relative to the plate, in plate axes.
    on_plate: the centre is within the plate square; dropped: fell off (latched until reset).
    """

    time_s: float
    x: float
    y: float
    z: float
    vx: float
    vy: float
    on_plate: bool
    dropped: bool


@dataclass(frozen=True)
class FrameTruth:
    """What a rendered frame shows: the ball (plate frame and pixel) at capture time."""

    ball: BallTruth
    pixel_u: float     # ball centre projected into the image (OpenCV pixel coordinates)
    pixel_v: float
    visible: bool      # the projected centre is inside the image


@dataclass(frozen=True)
class Snapshot:
    """Everything the renderer needs from one instant (copied, so physics can move on)."""

    time_s: float
    qpos: np.ndarray
    truth: BallTruth


class SimWorld:
    """The simulated arm + plate + ball. Single-threaded: call from one thread only."""

    def __init__(self, config: SimConfig = SimConfig(), knobs: DomainKnobs = DomainKnobs(),
                 urdf_text: Optional[str] = None, seed: int = 0):
        self.config, self.knobs = config, knobs
        self.urdf_text = urdf_text if urdf_text is not None else robot.robot_description()
        self.model, self.ids = build_model(self.urdf_text, config, knobs)
        self.data = mujoco.MjData(self.model)
        limits = robot.joint_limits(self.urdf_text)
        self.lower_rad = np.array([limits[n].lower for n in robot.JOINT_NAMES])
        self.upper_rad = np.array([limits[n].upper for n in robot.JOINT_NAMES])
        self.max_velocity_rad_s = np.array([limits[n].velocity for n in robot.JOINT_NAMES])
        self.speed_scaling = 1.0
        self.rng = np.random.default_rng(seed)
        self._pending: collections.deque = collections.deque()  # (apply at time_s, targets)
        self._target = np.zeros(6)
        self._dropped = False
        self._renderer = None
        self._plate_vel = np.zeros(6)
        self.reset()

    # ---- state -----------------------------------------------------------------------
    @property
    def time_s(self) -> float:
        return float(self.data.time)

    @property
    def physics_dt_s(self) -> float:
        return float(self.model.opt.timestep)

    def reset(self, joint_positions: Sequence[float] = robot.HOME_POSITIONS_RAD,
              ball_xy: Tuple[float, float] = (0.0, 0.0)) -> None:
        """Time 0, arm at `joint_positions` (held there), ball at rest on the plate at `ball_xy`."""
        mujoco.mj_resetData(self.model, self.data)
        self._pending.clear()
        self._dropped = False
        self.set_joint_positions(joint_positions)
        self.place_ball(*ball_xy)

    def set_joint_positions(self, q: Sequence[float]) -> None:
        """Teleport the arm to `q` at rest and hold it there (for test set-ups and reset)."""
        q = self._checked(q)
        self.data.qpos[self.ids.qpos_arm] = q
        self.data.qvel[self.ids.dof_arm] = 0.0
        self.data.ctrl[self.ids.actuators] = q
        self._target[:] = q
        self._pending.clear()
        mujoco.mj_forward(self.model, self.data)

    def place_ball(self, x: float, y: float, vx: float = 0.0, vy: float = 0.0) -> None:
        """Put the ball resting on the plate at (x, y) (plate frame, m), velocity (vx, vy) m/s."""
        p_W, R_WP = self.plate_pose()
        z = PLATE_THICKNESS_M / 2.0 + self.config.ball_radius_m
        a = self.ids.ball_qpos
        self.data.qpos[a:a + 3] = p_W + R_WP @ np.array([x, y, z])
        self.data.qpos[a + 3:a + 7] = (1.0, 0.0, 0.0, 0.0)
        d = self.ids.ball_dof
        self.data.qvel[d:d + 3] = R_WP @ np.array([vx, vy, 0.0])
        self.data.qvel[d + 3:d + 6] = 0.0
        self._dropped = False
        mujoco.mj_forward(self.model, self.data)

    # ---- commands and stepping -------------------------------------------------------
    def set_joint_targets(self, q: Sequence[float]) -> None:
        """Command 6 joint positions (rad). Raises CommandError (and keeps the last target)
        for a non-finite value, a wrong length or a position outside the URDF limits."""
        q = self._checked(q)
        self._pending.append((self.time_s + self.knobs.latency_s, q))

    def _checked(self, q: Sequence[float]) -> np.ndarray:
        try:
            q = np.array(q, dtype=float).reshape(6)
        except (TypeError, ValueError):
            raise CommandError(f"joint command must be 6 numbers, got {q!r}") from None
        if not np.all(np.isfinite(q)):
            raise CommandError(f"joint command has a non-finite value: {q.tolist()}")
        outside = (q < self.lower_rad) | (q > self.upper_rad)
        if np.any(outside):
            names = [n for n, bad in zip(robot.JOINT_NAMES, outside, strict=True) if bad]
            raise CommandError(f"joint command outside the limits for {names}: {q.tolist()}")
        return q

    def step(self, n: int = 1) -> None:
        """Advance physics by n steps of physics_dt_s.

        Raises SimulationError when the physics diverged (non-finite or huge state; MuJoCo
        then resets its data): the world is put back at rest at the last joint targets with
        the ball on the plate centre (time keeps going), so the caller can carry on.
        """
        dt = self.physics_dt_s
        acts = self.ids.actuators
        for _ in range(n):
            while self._pending and self._pending[0][0] <= self.time_s + 1e-12:
                self._target[:] = self._pending.popleft()[1]
            # slew-limit the servo setpoint to the joint velocity limit (x speed scaling)
            max_step = self.max_velocity_rad_s * (self.speed_scaling * dt)
            setpoint = self.data.ctrl[acts]
            self.data.ctrl[acts] = setpoint + np.clip(self._target - setpoint, -max_step, max_step)
            last_time_s = self.data.time
            mujoco.mj_step(self.model, self.data)
            if self.data.time < last_time_s:  # MuJoCo reset the data: it diverged
                self.reset(self._target.copy())
                self.data.time = last_time_s + dt  # time never runs backwards (it may be the clock)
                raise SimulationError(f"physics diverged at t={self.data.time:.3f} s (MuJoCo reset its "
                                      "state); world reset to the last joint targets")
        if not self._dropped:
            self._dropped = self._off_plate()

    def advance(self, duration_s: float) -> None:
        """Step physics for `duration_s` of simulated time (rounded to whole steps)."""
        self.step(max(0, int(round(duration_s / self.physics_dt_s))))

    # ---- readings --------------------------------------------------------------------
    def joint_positions(self) -> np.ndarray:
        return self.data.qpos[self.ids.qpos_arm].copy()

    def joint_velocities(self) -> np.ndarray:
        return self.data.qvel[self.ids.dof_arm].copy()

    def joint_efforts(self) -> np.ndarray:
        """Motor torque per joint (N m): servo torque plus the gravity compensation."""
        dofs = self.ids.dof_arm
        return self.data.actuator_force[self.ids.actuators] + self.data.qfrc_gravcomp[dofs]

    def plate_pose(self) -> Tuple[np.ndarray, np.ndarray]:
        """(p_W, R_WP): plate_center origin and rotation in the world (= base_link) frame."""
        body = self.ids.plate_body
        return self.data.xpos[body].copy(), self.data.xmat[body].reshape(3, 3).copy()

    @property
    def ball_dropped(self) -> bool:
        """True once the ball has left the plate (latched until reset()/place_ball())."""
        return self._dropped

    def _off_plate(self) -> bool:
        truth = self._truth(self.data)
        return not truth.on_plate or truth.z < -self.config.ball_radius_m

    def ball_truth(self) -> BallTruth:
        return self._truth(self.data)

    def _truth(self, data: mujoco.MjData) -> BallTruth:
        body = self.ids.plate_body
        p_W, R_WP = data.xpos[body], data.xmat[body].reshape(3, 3)
        a, d = self.ids.ball_qpos, self.ids.ball_dof
        ball_W = data.qpos[a:a + 3]
        # plate velocity at its origin, world axes: [angular; linear]
        mujoco.mj_objectVelocity(self.model, data, mujoco.mjtObj.mjOBJ_BODY, body, self._plate_vel, 0)
        omega_W, v_plate_W = self._plate_vel[:3], self._plate_vel[3:]
        r_W = ball_W - p_W
        v_rel_W = data.qvel[d:d + 3] - (v_plate_W + np.cross(omega_W, r_W))
        x, y, z = R_WP.T @ r_W
        vx, vy, _ = R_WP.T @ v_rel_W
        half = PLATE_SIDE_M / 2.0
        on_plate = abs(x) <= half and abs(y) <= half
        return BallTruth(float(data.time), float(x), float(y), float(z), float(vx), float(vy),
                         bool(on_plate), self._dropped)

    def detected_ball(self) -> Tuple[float, float]:
        """Truth (x, y) plus Gaussian noise of std knobs.detection_noise_m (truth-fed mode)."""
        truth = self.ball_truth()
        sigma = self.knobs.detection_noise_m
        noise = self.rng.normal(0.0, sigma, 2) if sigma > 0.0 else (0.0, 0.0)
        return truth.x + float(noise[0]), truth.y + float(noise[1])

    # ---- camera ----------------------------------------------------------------------
    def snapshot(self) -> Snapshot:
        """A copy of the pose of everything, for rendering in another thread."""
        return Snapshot(self.time_s, self.data.qpos.copy(), self.ball_truth())

    def camera_pose(self) -> Tuple[np.ndarray, np.ndarray]:
        """(position, R_WC) of the overhead camera (MuJoCo camera axes: x right, y up, looks -z)."""
        cam = self.ids.camera
        return self.data.cam_xpos[cam].copy(), self.data.cam_xmat[cam].reshape(3, 3).copy()

    def project_world(self, p_W: Sequence[float]) -> Tuple[float, float]:
        """Pixel (u, v) of a world point, OpenCV convention (u right, v down)."""
        c_W, R_WC = self.camera_pose()
        X, Y, Z = R_WC.T @ (np.asarray(p_W, dtype=float) - c_W)
        fx, fy, cx, cy = camera_intrinsics(self.config.camera)
        depth = -Z
        return cx + fx * X / depth, cy - fy * Y / depth

    def project_plate(self, x: float, y: float, z: float = PLATE_THICKNESS_M / 2.0) -> Tuple[float, float]:
        """Pixel (u, v) of a point given in the plate frame (default: on the top surface)."""
        p_W, R_WP = self.plate_pose()
        return self.project_world(p_W + R_WP @ np.array([x, y, z]))

    def frame_truth(self, truth: Optional[BallTruth] = None) -> FrameTruth:
        truth = truth or self.ball_truth()
        a = self.ids.ball_qpos
        u, v = self.project_world(self.data.qpos[a:a + 3])
        cam = self.config.camera
        visible = math.isfinite(u) and 0 <= u < cam.width_px and 0 <= v < cam.height_px
        return FrameTruth(truth, float(u), float(v), bool(visible))

    def render(self) -> Tuple[np.ndarray, FrameTruth]:
        """Render the overhead camera now: (H x W x 3 uint8 BGR, FrameTruth). Calling thread."""
        from ball_balance.sim.camera import CameraRenderer

        if self._renderer is None:
            self._renderer = CameraRenderer(self.model, self.config.camera, self.knobs.exposure)
        image = self._renderer.render(self.data.qpos)
        return image, self.frame_truth()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
