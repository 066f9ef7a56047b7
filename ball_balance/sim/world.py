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
`render_exposure(s)` gives the raw frames over a shutter time (motion blur, with
`history_s` set).

Disturbances: `place_ball(x, y, vx, vy)` releases the ball rolling (spin consistent with
rolling, so no speed is lost to slip), `push_ball(dvx, dvy)` is an impulse with the matching
spin, `apply_force(fx, fy, duration_s)` a timed external force on the ball's centre,
`hold_force(fx, fy)` a constant one until changed.
It renders in the calling thread; the ROS component uses `snapshot()` + CameraRenderer in
its own thread instead.
"""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass, replace
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
        if knobs.ball_shell is not None:  # the domain chooses the ball (solid or hollow)
            config = replace(config, ball_shell=knobs.ball_shell)
        self.config, self.knobs = config, knobs
        self.urdf_text = urdf_text if urdf_text is not None else robot.robot_description()
        self.model, self.ids = build_model(self.urdf_text, config, knobs)
        self.data = mujoco.MjData(self.model)
        limits = robot.joint_limits(self.urdf_text)
        self.lower_rad = np.array([limits[n].lower for n in robot.JOINT_NAMES])
        self.upper_rad = np.array([limits[n].upper for n in robot.JOINT_NAMES])
        self.max_velocity_rad_s = np.array([limits[n].velocity for n in robot.JOINT_NAMES])
        self.max_effort_n_m = np.array([limits[n].effort for n in robot.JOINT_NAMES])
        dofs = self.ids.dof_arm   # M_ii in data.M (CSR rows, the diagonal last in each row)
        self._mass_diag = self.model.M_rowadr[dofs] + self.model.M_rownnz[dofs] - 1
        self._setpoint = np.zeros(6)
        # room to the limits of [setpoint, setpoint, joint, joint] (down, up, down, up), less the margin
        self._room_sign = np.repeat([1.0, -1.0, 1.0, -1.0], 6)
        self._room_offset = np.concatenate((-self.lower_rad, self.upper_rad, -self.lower_rad, self.upper_rad)) \
            - self.LIMIT_MARGIN_RAD
        self.limit_guard_count = 0      # physics steps where the last-resort limit guard acted
        self.speed_scaling = 1.0
        self.rng = np.random.default_rng(seed)
        self._pending: collections.deque = collections.deque()  # (apply at time_s, targets)
        self._target = np.zeros(6)
        self._dropped = False
        self._renderer = None
        self._plate_vel = np.zeros(6)
        self._forces: list = []     # (end time_s, [force N, torque N m] in world axes) on the ball
        self._held_force = None     # the entry of _forces that hold_force put there
        self.history_s = 0.0        # keep (time, qpos) of this much past (motion blur)
        self._history: collections.deque = collections.deque()
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
        self.clear_forces()
        self._history.clear()
        self._dropped = False
        self.set_joint_positions(joint_positions)
        self.place_ball(*ball_xy)

    def set_joint_positions(self, q: Sequence[float]) -> None:
        """Teleport the arm to `q` at rest and hold it there (for test set-ups and reset)."""
        q = self._checked(q)
        self.data.qpos[self.ids.qpos_arm] = q
        self.data.qvel[self.ids.dof_arm] = 0.0
        self.data.ctrl[self.ids.actuators] = q
        self._setpoint[:] = q
        self._target[:] = q
        self._pending.clear()
        mujoco.mj_forward(self.model, self.data)

    def place_ball(self, x: float, y: float, vx: float = 0.0, vy: float = 0.0) -> None:
        """Put the ball on the plate at (x, y) (plate frame, m), rolling at (vx, vy) m/s
        relative to the plate, its spin consistent with rolling (no slip at the contact) and
        with the plate's own motion, so none of the speed is lost to slip."""
        p_W, R_WP = self.plate_pose()
        z = PLATE_THICKNESS_M / 2.0 + self.config.ball_radius_m
        a = self.ids.ball_qpos
        self.data.qpos[a:a + 3] = p_W + R_WP @ np.array([x, y, z])
        self.data.qpos[a + 3:a + 7] = (1.0, 0.0, 0.0, 0.0)
        d = self.ids.ball_dof
        self.data.qvel[d:d + 6] = 0.0
        mujoco.mj_forward(self.model, self.data)
        omega_W, v_plate_W = self._plate_velocity(self.data)
        r_W = self.data.qpos[a:a + 3] - p_W
        self.data.qvel[d:d + 3] = v_plate_W + np.cross(omega_W, r_W)
        self.data.qvel[d + 3:d + 6] = omega_W    # identity orientation: body axes = world axes
        self._dropped = False
        self._add_rolling_velocity(vx, vy)

    def push_ball(self, dvx: float, dvy: float) -> None:
        """An impulse: the ball's velocity relative to the plate changes by (dvx, dvy) m/s
        (plate axes) with the matching change of spin, so it keeps rolling without slip."""
        self._add_rolling_velocity(dvx, dvy)

    def apply_force(self, fx_n: float, fy_n: float, duration_s: float, fz_n: float = 0.0) -> None:
        """An external force (N, plate axes at the time of the call) on the ball's centre for
        the next `duration_s` of simulated time (whole physics steps); forces add up.
        Friction at the contact makes the spin follow, as for a finger pushing the ball."""
        self.apply_wrench((fx_n, fy_n, fz_n), (0.0, 0.0, 0.0), duration_s)

    def hold_force(self, fx_n: float, fy_n: float) -> None:
        """A constant force (N, plate axes at the time of the call) on the ball's centre from now
        until the next hold_force, which replaces it ((0, 0) ends it), clear_forces() or reset().
        The timed forces of apply_force / apply_wrench add to it."""
        if not (math.isfinite(fx_n) and math.isfinite(fy_n)):
            raise CommandError(f"force ({fx_n}, {fy_n}) N must be finite")
        self._forces = [entry for entry in self._forces if entry is not self._held_force]
        self._held_force = None
        if fx_n != 0.0 or fy_n != 0.0:
            self.apply_wrench((fx_n, fy_n, 0.0), (0.0, 0.0, 0.0), math.inf)
            self._held_force = self._forces[-1]

    def apply_wrench(self, force_n: Sequence[float], torque_n_m: Sequence[float], duration_s: float,
                     in_plate_axes: bool = True) -> None:
        """Force (N) and torque (N m) on the ball's centre for `duration_s` s (at least one
        physics step; math.inf: until clear_forces()), in plate axes at the time of the call or
        in world axes."""
        values = np.concatenate([np.asarray(force_n, dtype=float).reshape(3),
                                 np.asarray(torque_n_m, dtype=float).reshape(3)])
        if not np.all(np.isfinite(values)) or not duration_s >= 0.0:
            raise CommandError(f"wrench {values.tolist()} for {duration_s} s: needs finite numbers "
                               "and a duration >= 0")
        R = self.plate_pose()[1] if in_plate_axes else np.eye(3)
        end = self.time_s + max(duration_s, self.physics_dt_s)
        self._forces.append((end, np.concatenate([R @ values[:3], R @ values[3:6]])))

    def clear_forces(self) -> None:
        """End every external force and torque on the ball now (the held one too)."""
        self._forces = []
        self._held_force = None
        self.data.xfrc_applied[self.ids.ball_body, :] = 0.0

    def _add_rolling_velocity(self, dvx: float, dvy: float) -> None:
        if not (math.isfinite(dvx) and math.isfinite(dvy)):
            raise CommandError(f"ball velocity ({dvx}, {dvy}) m/s must be finite")
        if dvx == 0.0 and dvy == 0.0:
            return
        _, R_WP = self.plate_pose()
        dv_W = R_WP @ np.array([dvx, dvy, 0.0])
        # rolling without slip: contact point (at -r n from the centre) at rest relative to
        # the plate, so d_omega = n x dv / r
        domega_W = np.cross(R_WP[:, 2], dv_W) / self.config.ball_radius_m
        d = self.ids.ball_dof
        R_WB = self.data.xmat[self.ids.ball_body].reshape(3, 3)
        self.data.qvel[d:d + 3] += dv_W
        self.data.qvel[d + 3:d + 6] += R_WB.T @ domega_W  # a free joint's spin is in body axes
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
            self.data.ctrl[acts] = self._servo_setpoint(dt)
            self._apply_forces()
            last_time_s = self.data.time
            mujoco.mj_step(self.model, self.data)
            if self.data.time < last_time_s:  # MuJoCo reset the data: it diverged
                self.reset(self._target.copy())
                self.data.time = last_time_s + dt  # time never runs backwards (it may be the clock)
                raise SimulationError(f"physics diverged at t={self.data.time:.3f} s (MuJoCo reset its "
                                      "state); world reset to the last joint targets")
            self._guard_limits()
            if self.history_s > 0.0:
                self._history.append((self.data.time, self.data.qpos.copy()))
                while self._history and self._history[0][0] < self.data.time - self.history_s - 1e-9:
                    self._history.popleft()
        if not self._dropped:
            self._dropped = self._off_plate()

    # Fraction of the joint's torque (URDF effort) / inertia used to brake before a position
    # limit: the rest is left for coupling from the other joints and for tracking.
    BRAKE_TORQUE_SHARE = 0.5
    # The servo never asks for more than this share of the velocity limit (transients and
    # coupling from the other joints stay below the limit itself).
    VELOCITY_SHARE = 0.95
    # The setpoint stops this far inside a position limit: the joint-limit constraint is soft
    # and coupling from the other joints moves a joint a fraction of a milliradian.
    LIMIT_MARGIN_RAD = 1e-3

    def _servo_setpoint(self, dt: float) -> np.ndarray:
        """The position servo's setpoint for this physics step: a velocity-limited position servo.

        1. The setpoint moves toward the target at most at the URDF velocity limit (x speed
           scaling), and toward a position limit no faster than the joint can brake from
           before the limit: v <= sqrt(2 a d), a = BRAKE_TORQUE_SHARE x effort / M_ii (M_ii at
           the current pose), d = the room left to the limit (minus LIMIT_MARGIN_RAD).
        2. The servo (kp, kv with kp / kv = 1 / servo_lag) settles at velocity = error / lag, so
           clamping the error it sees to lag x (that same velocity bound) means it never
           drives the joint faster than the limit or into a position limit, even after torque
           saturation or when the other joints push it (what would otherwise make it overshoot).
        Both stop LIMIT_MARGIN_RAD inside the position limits; the servo asks for at most
        VELOCITY_SHARE of the velocity limit (coupling adds a few per cent).
        """
        q = self.data.qpos[self.ids.qpos_arm]
        sp = self._setpoint
        accel = self.BRAKE_TORQUE_SHARE * self.max_effort_n_m / self.data.M[self._mass_diag]
        # velocity that can still be braked to zero within the room left, for the setpoint and
        # the joint, downward and upward (one vector of 24: this runs every physics step)
        room = self._room_sign * np.concatenate((sp, sp, q, q)) + self._room_offset
        vmax = self.max_velocity_rad_s * self.speed_scaling
        v = np.minimum(np.concatenate((vmax, vmax, vmax, vmax)),
                       np.sqrt(2.0 * np.concatenate((accel, accel, accel, accel)) * np.maximum(room, 0.0)))
        sp += np.minimum(np.maximum(self._target - sp, -v[0:6] * dt), v[6:12] * dt)
        lag = self.config.servo_lag_s * self.VELOCITY_SHARE
        return np.minimum(np.maximum(sp, q - v[12:18] * lag), q + v[18:24] * lag)

    def _guard_limits(self) -> None:
        """Last resort, as a drive's own limits: a joint past a position limit is put back on
        it with no velocity outward, one faster than its velocity limit is slowed to it.
        The servo keeps to the limits by itself in everything but extreme cases (every joint
        swinging at full speed at once, where the coupling exceeds the URDF efforts); each
        step where the guard acted is counted in `limit_guard_count`."""
        qa, da = self.ids.qpos_arm, self.ids.dof_arm
        q, v = self.data.qpos[qa], self.data.qvel[da]
        vmax = self.max_velocity_rad_s
        low, high = q < self.lower_rad, q > self.upper_rad
        fast = np.abs(v) > vmax
        if not (low | high | fast).any():
            return
        self.limit_guard_count += 1
        q = np.clip(q, self.lower_rad, self.upper_rad)
        v = np.clip(v, -vmax, vmax)
        v[low] = np.maximum(v[low], 0.0)
        v[high] = np.minimum(v[high], 0.0)
        self.data.qpos[qa], self.data.qvel[da] = q, v
        mujoco.mj_forward(self.model, self.data)

    def _apply_forces(self) -> None:
        body = self.ids.ball_body
        self.data.xfrc_applied[body, :] = 0.0
        if not self._forces:
            return
        now = self.data.time
        # the same tuples kept: hold_force finds its own by identity
        self._forces = [entry for entry in self._forces if entry[0] > now + 1e-12]
        for _, wrench_W in self._forces:
            self.data.xfrc_applied[body, :] += wrench_W

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

    def _plate_velocity(self, data: mujoco.MjData) -> Tuple[np.ndarray, np.ndarray]:
        """(omega, v) of the plate at its origin, world axes."""
        mujoco.mj_objectVelocity(self.model, data, mujoco.mjtObj.mjOBJ_BODY, self.ids.plate_body,
                                 self._plate_vel, 0)
        return self._plate_vel[:3].copy(), self._plate_vel[3:].copy()

    def ball_truth(self) -> BallTruth:
        return self._truth(self.data)

    def _truth(self, data: mujoco.MjData) -> BallTruth:
        body = self.ids.plate_body
        p_W, R_WP = data.xpos[body], data.xmat[body].reshape(3, 3)
        a, d = self.ids.ball_qpos, self.ids.ball_dof
        ball_W = data.qpos[a:a + 3]
        omega_W, v_plate_W = self._plate_velocity(data)
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
        from ball_balance.sim.camera import develop

        return develop([self._raw_render(self.data.qpos)], self.knobs.exposure), self.frame_truth()

    def render_exposure(self, exposure_s: float, samples: int = 0) -> list:
        """Raw frames (BGR uint8, no gain) spread over the last `exposure_s` of simulated time,
        for motion blur (camera.develop averages them); one frame now when exposure_s is 0.
        Needs `history_s >= exposure_s` set before stepping; `samples` 0: one per 2 ms (2-5)."""
        if exposure_s <= 0.0 or not self._history:
            return [self._raw_render(self.data.qpos)]
        n = samples or int(min(5, max(2, round(exposure_s / 0.002) + 1)))
        times = np.array([h[0] for h in self._history])
        frames = []
        for k in range(n):
            t = self.time_s - exposure_s * k / (n - 1)
            frames.append(self._raw_render(self._history[int(np.argmin(np.abs(times - t)))][1]))
        return frames

    def _raw_render(self, qpos: np.ndarray) -> np.ndarray:
        from ball_balance.sim.camera import CameraRenderer

        if self._renderer is None:
            self._renderer = CameraRenderer(self.model, self.config.camera, 1.0)
        return self._renderer.render(qpos)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
