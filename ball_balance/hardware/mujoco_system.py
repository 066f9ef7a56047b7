"""`ball_balance/MujocoSystem`: the simulated UR arm as a controller_manager_py system component.

A thin adapter around ball_balance.sim.SimWorld (the physics) and CameraThread (the camera):

- interfaces (from the robot description): per joint a `position` command and
  `position`/`velocity`/`effort` states; `speed_scaling/speed_scaling_factor` (1.0) for the
  scaled trajectory controller; extra states `ball/x`, `ball/y`, `ball/vx`, `ball/vy`
  (plate frame, truth) and `ball/dropped` (1.0 once the ball fell off).
- time: `read()` advances physics, in lock-step by the cycle period (pacing=lockstep; the
  manager's wall-clock loop then paces it) or to follow the wall clock (pacing=realtime);
  with sim_time=true the component owns the manager's clock (`now()`) and publishes /clock
  (starting at 0: run the other nodes with use_sim_time:=true); with sim_time=false the
  manager keeps the wall clock and message stamps are wall-clock times (pair it with
  pacing=realtime so simulated time keeps up with them).
  `write()` hands the position commands to the servos (non-finite or out-of-limit commands
  are refused, counted and logged throttled; the last good target is kept).
- topics (when the manager has a node): /camera/image_raw (bgr8) and /camera/camera_info
  (sensor-data QoS, best effort keep-last 1, as docs/design.md specifies; whole frames need the
  DDS settings of config/dds, docs/transport.md; image_reliable=true publishes reliable;
  stamp = capture time; rendered and published by a child process, camera_process=true, or
  a thread of the manager), /sim/ball_truth
  (BallState, plate frame), /sim/ball_dropped (Bool, transient local), /clock; with
  truth_fed=true also /ball_state from the truth plus detection noise (no tracker needed).
  Services and topics to drive the simulation (as mujoco_ros2_control users have them,
  with std_srvs / geometry_msgs types; services reply once the loop has applied the
  request; see docs/simulation.md):
  /sim/reset_ball (std_srvs/Trigger): ball back to rest at the plate centre;
  /sim/reset_world (std_srvs/Trigger): arm at home at rest, ball at (ball_x, ball_y) at
  rest (time keeps running: the clock never goes backwards);
  /sim/set_pause (std_srvs/SetBool): data=true stops physics and the simulated clock;
  /sim/step_simulation (std_srvs/Trigger): while paused, advance `step_simulation_steps`
  physics steps;
  /sim/ball_wrench (geometry_msgs/WrenchStamped, topic): force [N] and torque [N m] on the
  ball's centre, axes of header.frame_id (plate_center, default, or base_link/world), for
  `wrench_duration` s from receipt (a timed external wrench; keep publishing for longer);
  /sim/push_ball (geometry_msgs/Vector3Stamped, topic): an impulse, the ball's velocity
  changes by the vector [m/s] (plate axes), spin kept consistent with rolling;
  /sim/ball_pushed (geometry_msgs/Vector3Stamped, topic, published): every push applied
  (asked for, or the domain's), stamped with the simulated time it acted;
  /sim/ball_force (geometry_msgs/Vector3Stamped, topic, published, transient local): the
  constant force on the ball's centre in effect [N, plate axes] (the held one and the
  domain's force steps), at configure and at every change, stamped with the simulated time
  it began;
  /sim/set_ball_force (ball_tracker_msgs/SetBallForce): a constant force on the ball's centre
  held from now on, as the plate tilt that rolls the ball the same way (`ball_force_deg`,
  `ball_force_dir_deg`, the parameters that set it at start); a bad request is refused with
  the reason and changes nothing;
  /sim/inject_hardware_error (std_srvs/Trigger): the next read() returns ERROR, as a driver's
  does when it loses the robot (the manager then deactivates its controllers and runs on_error).
  Requests are taken by the real-time loop at its next read().
- the domain's disturbances, on simulated time from the start as in a benchmark episode: its
  pushes (`pushes`, every push_interval_s) and force steps (`force_2deg`: on at 5 s, turned
  at 9 s, off at 13 s; DomainKnobs.force_steps); its plate mounting is built into the model.

Hardware parameters (`<hardware><param name=...>` in the URDF; see SCHEMA), optionally from
a YAML file given as `sim_config` (URDF params win).
"""
from __future__ import annotations

import collections
import math
import time as _time
from concurrent.futures import Future
from typing import Dict, Mapping, Optional

import numpy as np

from ball_balance import robot
from ball_balance.sim.config import CameraConfig, DomainKnobs, SimConfig, SimConfigError
from ball_balance.sim.lockstep import FrameAnswerGate
from ball_balance.sim.world import CommandError, SimulationError, SimWorld
from controller_manager_py.hardware_interface import CallbackReturn, HardwareInfo, State, SystemInterface, return_type
from controller_manager_py.parameters import Param, ParameterError, validate
from controller_manager_py.ros.params_files import ParamsFileError, load_yaml_text
from controller_manager_py.text_files import TextFileError, read_text_file

_KNOB = "domain knob; empty = the domain's value"
SCHEMA = (
    Param("physics_dt", 0.001, "MuJoCo timestep", "s", 1e-4, 0.005),
    Param("servo_lag", 0.005, "joint servo time constant", "s", 5e-4, 0.1),
    Param("ball_shell", True, "thin-shell ball (rolls at 3/5 g sin(tilt)); false: solid (5/7)"),
    Param("pacing", "lockstep", "lockstep: advance one cycle period per cycle, and hold before the next camera "
          "frame until the last one is answered (a /ball_state of its stamp, then a /plate_cmd), so a slower "
          "machine slows simulated time, not the control; realtime: follow the wall clock",
          choices=("lockstep", "realtime"), user_facing=True),
    Param("cycle_period", 0.002, "sim time per cycle when the manager gives no usable period", "s", 1e-4, 0.1),
    Param("sim_time", True, "own the manager's clock and publish /clock", user_facing=True),
    Param("clock_rate_hz", 100.0, "/clock publishing rate (sim time); every node on simulated time wakes for "
          "each tick, so its time advances in steps of this period", "Hz", 1.0, 10000.0),
    Param("camera_enabled", True, "render and publish the overhead camera", user_facing=True),
    Param("camera_rate_hz", 30.0, "camera frame rate (sim time)", "Hz", 0.1, 1000.0, user_facing=True),
    Param("camera_width", 640, "image width", "px", 1, 4096, user_facing=True),
    Param("camera_height", 480, "image height", "px", 1, 4096, user_facing=True),
    Param("camera_fovy_deg", 45.0, "vertical field of view", "deg", 5.0, 150.0),
    Param("camera_height_m", 0.65, "camera height above the plate at home", "m", 0.1, 5.0),
    Param("camera_antialias_samples", 0, "MSAA samples (0, 1, 2, 4, 8): 4 costs ~2.5x render time",
          choices=(0, 1, 2, 4, 8)),
    Param("camera_frame_id", "camera_optical_frame", "frame_id of the image messages"),
    Param("camera_process", True, "render and publish the camera in a child process (never holds the "
          "manager's interpreter lock); false: a thread of the manager"),
    Param("camera_render_threads", 0, "render threads of the software renderer (Mesa llvmpipe, LP_NUM_THREADS) "
          "in the camera process (camera_process=true); 0: Mesa's default, one per CPU. 1 leaves a CPU to the "
          "manager's loop while a frame renders: a higher real-time factor in lock-step pacing on 2 CPUs, a "
          "slower frame (docs/simulation.md)", "", 0, 256),
    Param("camera_extra_render_s", 0.0, "added to every frame's render time (a slower renderer, for tests and "
          "benchmarks of how the graph copes)", "s", 0.0, 10.0),
    Param("image_reliable", False, "publish images reliable (keep-last 2) instead of sensor-data QoS "
          "(best effort, keep-last 1)"),
    Param("truth_rate_hz", 100.0, "/sim/ball_truth rate (sim time)", "Hz", 0.1, 1000.0),
    Param("truth_fed", False, "also publish /ball_state from the truth plus detection noise"),
    Param("latency_trace", False, "publish /sim/latency_trace (frame captured, frame rendered, new joint "
          "target written; benchmarks/latency_budget_bench.py)"),
    Param("domain", "standard", "evaluation domain (docs/design.md section 7)", user_facing=True),
    Param("seed", 0, "seed of the domain's random knobs and of the detection noise", min=0, user_facing=True),
    Param("ball_mass_kg", "", _KNOB), Param("ball_friction", "", _KNOB), Param("gravity_scale", "", _KNOB),
    Param("detection_noise_m", "", _KNOB), Param("latency_s", "", _KNOB), Param("light_scale", "", _KNOB),
    Param("exposure", "", _KNOB),
    Param("plate_mount_tilt_deg", "", _KNOB + " (the plate mounted this far off level on the flange)"),
    Param("plate_mount_axis_deg", "", _KNOB + " (the horizontal plate axis, from +x, it is tilted about: the "
          "ball rolls towards this direction less 90 deg)"),
    Param("ball_x", 0.0, "initial ball position, plate frame", "m", -0.2, 0.2, user_facing=True),
    Param("ball_y", 0.0, "initial ball position, plate frame", "m", -0.2, 0.2, user_facing=True),
    Param("sim_config", "", "YAML file with any of these parameters (URDF params win)", user_facing=True),
    Param("robot_description_file", "", "URDF the world is built from; empty = config/ur5e_ball_balance.urdf",
          user_facing=True),
    Param("start_paused", False, "come up paused (physics and clock stopped) until /sim/set_pause data=false: "
          "the graph scripts resume once every node is up, so nothing moves the ball before a controller acts",
              user_facing=True),
    Param("step_simulation_steps", 1, "physics steps per /sim/step_simulation call (while paused)", "", 1, 100000),
    Param("wrench_duration", 0.1, "how long one /sim/ball_wrench message acts", "s", 0.0, 10.0),
    Param("ball_force_deg", 0.0, "a constant force on the ball's centre from the start, equal to a plate tilted "
          "this far (F = m g sin(angle)); change it while running with /sim/set_ball_force", "deg", 0.0, 10.0,
          user_facing=True),
    Param("ball_force_dir_deg", 0.0, "the direction the force pushes the ball, plate axes from +x towards +y",
          "deg", -360.0, 360.0, user_facing=True),
)
_KNOB_NAMES = ("ball_mass_kg", "ball_friction", "gravity_scale", "detection_noise_m", "latency_s",
               "light_scale", "exposure", "plate_mount_tilt_deg", "plate_mount_axis_deg")
_PARAMS = {p.name: p for p in SCHEMA}


def parse_hardware_params(raw: Mapping[str, str]) -> Mapping[str, object]:
    """URDF `<param>` strings (+ the optional sim_config YAML) -> validated values (ParameterError)."""
    values: Dict[str, object] = {}
    path = raw.get("sim_config", "")
    if path:

        try:
            loaded = load_yaml_text(read_text_file(path, "sim config"), f"the values in '{path}'")
        except (TextFileError, ParamsFileError) as error:
            raise ParameterError(f"parameter 'sim_config': {error}") from None
        if not isinstance(loaded, dict):
            raise ParameterError(f"parameter 'sim_config': {path} must hold a mapping")
        values.update(loaded)
    defaults = {p.name: p.default for p in SCHEMA}
    for name, text in raw.items():
        if name in defaults:
            values[name] = _from_text(defaults[name], text)
        else:
            values[name] = text  # validate() names it as unknown
    for name in _KNOB_NAMES:  # knobs are numbers when given, "" when not
        if name in values and not isinstance(values[name], str):
            values[name] = str(values[name])
    return validate(SCHEMA, values)


def _from_text(default, text):
    if not isinstance(text, str):
        return text
    text = text.strip()
    try:
        if isinstance(default, bool):
            return {"true": True, "false": False, "1": True, "0": False}.get(text.lower(), text)
        if isinstance(default, int):
            return int(text)
        if isinstance(default, float):
            return float(text)
    except ValueError:
        return text
    return text


def build_sim(params: Mapping[str, object]):
    """(SimConfig, DomainKnobs) from validated parameters (SimConfigError names a bad value)."""
    camera = CameraConfig(width_px=params["camera_width"], height_px=params["camera_height"],
                          fovy_deg=params["camera_fovy_deg"], height_above_plate_m=params["camera_height_m"],
                          rate_hz=params["camera_rate_hz"], antialias_samples=params["camera_antialias_samples"])
    config = SimConfig(physics_dt_s=params["physics_dt"], servo_lag_s=params["servo_lag"],
                       ball_shell=params["ball_shell"], camera=camera)
    knobs = DomainKnobs.sample(params["domain"], params["seed"]).as_dict()
    for name in _KNOB_NAMES:
        text = params[name]
        if text != "":
            try:
                knobs[name] = float(text)
            except ValueError:
                raise SimConfigError(f"{name} = {text!r} must be a number") from None
    return config, DomainKnobs(**knobs)


def _full_description(info: HardwareInfo, path: str) -> str:
    """The whole URDF (the manager hands components only their <ros2_control> block)."""
    text = getattr(info, "robot_description", "") or ""
    if text:
        return text
    try:
        return read_text_file(path or robot.robot_description_path(), "robot description")
    except TextFileError as error:
        raise robot.RobotDescriptionError(f"robot_description_file: {error}") from None


class _InjectedError(Exception):
    """/sim/inject_hardware_error: read() fails once."""


class MujocoSystem(SystemInterface):
    provides_clock = True

    def __init__(self):
        super().__init__()
        self.world: Optional[SimWorld] = None
        self.camera = None
        self.ros = None
        self._stepped_forces = []   # (end s, fx N, fy N) of the domain's force steps acting
        self._next_force_change_s = math.inf   # a step begins or one acting ends
        self._announced_force = None   # (fx, fy) N last said on /sim/ball_force
        self.commands_refused = 0
        self.overruns = 0
        self.answers: Optional[FrameAnswerGate] = None
        self._last_warn = -math.inf
        self._last_behind_warn = -math.inf

    # ---- lifecycle (executor thread) -----------------------------------------------------
    def on_init(self, info: HardwareInfo) -> CallbackReturn:
        """Load time (-> unconfigured): validate params, build the world (ERROR names a bad value)."""
        result = super().on_init(info)
        if result != CallbackReturn.SUCCESS:
            return result
        try:
            self.params = parse_hardware_params(info.hardware_parameters)
            config, knobs = build_sim(self.params)
            urdf = _full_description(info, self.params["robot_description_file"])
            joints = [j.name for j in info.joints]
            if sorted(joints) != sorted(robot.JOINT_NAMES):
                raise SimConfigError(f"<ros2_control> must list the joints {list(robot.JOINT_NAMES)}, got {joints}")
            self.world = SimWorld(config, knobs, urdf_text=urdf, seed=self.params["seed"])
        except (ParameterError, SimConfigError, robot.RobotDescriptionError) as error:
            self.get_logger().error(f"{info.name} (ball_balance/MujocoSystem): {error}")
            return CallbackReturn.ERROR
        self.provides_clock = bool(self.params["sim_time"])
        self.world.place_ball(self.params["ball_x"], self.params["ball_y"])
        self.ball_force = (self.params["ball_force_deg"], self.params["ball_force_dir_deg"])
        self._hold_ball_force()
        self._pos_cmd = [self.command_handles[f"{n}/position"] for n in robot.JOINT_NAMES]
        self._pos = [self.state_handles[f"{n}/position"] for n in robot.JOINT_NAMES]
        self._vel = [self.state_handles.get(f"{n}/velocity") for n in robot.JOINT_NAMES]
        self._eff = [self.state_handles.get(f"{n}/effort") for n in robot.JOINT_NAMES]
        self._ball = [self.state_handles[f"ball/{k}"] for k in ("x", "y", "vx", "vy", "dropped")]
        self._speed_scaling = self.state_handles.get("speed_scaling/speed_scaling_factor")
        gpio = next((g for g in info.gpios if g.name == "speed_scaling"), None)
        if gpio is not None:  # as the UR driver: <gpio name="speed_scaling"><param initial_...>
            text = gpio.parameters.get("initial_speed_scaling_factor", "1")
            try:
                factor = float(text)
            except ValueError:
                factor = math.nan
            if not 0.0 < factor <= 1.0:
                self.get_logger().error(f"{info.name}: initial_speed_scaling_factor = {text!r} must be in (0, 1]")
                return CallbackReturn.ERROR
            self.world.speed_scaling = factor
        self._target = np.array(robot.HOME_POSITIONS_RAD)
        self._requests = collections.deque()   # callables from other threads, run in read()
        self.paused = self.params["start_paused"]
        self._steps_requested = 0
        self._steps_waiting = []   # futures of the step requests taken, resolved once stepped
        self._copy_states()
        return CallbackReturn.SUCCESS

    def export_unlisted_state_interfaces(self):
        """The ball's true state as extra state interfaces (called in on_init)."""
        return [("ball", k) for k in ("x", "y", "vx", "vy", "dropped")]

    def on_configure(self, previous_state: State) -> CallbackReturn:
        """unconfigured -> inactive: publishers, reset service, camera thread. Physics runs from now."""
        node = self.get_node()
        if node is not None:
            from ball_balance.hardware.sim_ros import SimRosIo

            self.ros = SimRosIo(node, self.world, self.params, self)
            if not self.provides_clock:
                self.ros.stamp_offset_s = _time.time() - self.world.time_s
        if self.params["camera_enabled"] and self.params["camera_process"]:
            from ball_balance.hardware.camera_process import CameraProcess, PublishSettings

            publish = None
            if self.ros is not None:
                publish = PublishSettings(self.params["camera_frame_id"], self.params["image_reliable"],
                                          self.ros.stamp_offset_s, self.params["latency_trace"],
                                          node.context.get_domain_id())
            self.camera = CameraProcess(self.world.model, self.world.config.camera, self.world.knobs.exposure,
                                        publish, self._on_camera_error, self.params["camera_render_threads"],
                                        self.params["camera_extra_render_s"])
            self.camera.start()
        elif self.params["camera_enabled"]:
            from ball_balance.sim.camera import CameraThread

            if self.params["camera_render_threads"]:
                self.get_logger().warning(f"{self.get_name()}: camera_render_threads applies to the camera process "
                                          "(camera_process: true) only; ignored")

            self.camera = CameraThread(self.world.model, self.world.config.camera, self.world.knobs.exposure,
                                       self._on_frame, self._on_camera_error)
            self.camera.start()
        self._next_frame_s = self.world.time_s
        frames = self.params["camera_enabled"] or self.params["truth_fed"]
        self.answers = (FrameAnswerGate() if frames and self.params["pacing"] == "lockstep" and self.ros is not None
                        else None)
        if self.answers is not None:
            self.ros.follow_answers(self.answers, self.camera)
        self._next_truth_s = self.world.time_s
        # the domain's pushes (`pushes`): every push_interval_s, a seeded direction
        self._next_push_s = self.world.knobs.push_interval_s if self.world.knobs.push_speed_m_s > 0 else math.inf
        self._push_rng = np.random.default_rng(self.params["seed"] + 104729)
        # the domain's force steps (force_1deg ...): on, turned, off at the benchmark's times
        self._force_steps = collections.deque(self.world.knobs.force_steps())
        self._stepped_forces = []
        self._next_force_change_s = self._next_force_change()
        self._announced_force = None
        self._announce_force()
        self._next_clock_s = self.world.time_s
        self._wall_anchor = None
        if not self.introspection:  # once, also after cleanup + configure
            self.register_introspection("ball_x", lambda: self._ball[0].value)
            self.register_introspection("ball_y", lambda: self._ball[1].value)
            self.register_introspection("commands_refused", lambda: float(self.commands_refused))
            self.register_introspection("pacing_overruns", lambda: float(self.overruns))
            self.register_introspection("lockstep_frames_given_up",
                                        lambda: float(self.answers.frames_given_up if self.answers else 0))
            # /sim/push_ball, /sim/ball_wrench and /sim/set_ball_force refused (bad or beyond limits)
            self.register_introspection("disturbances_refused", lambda: float(
                self.ros.refused_disturbances + self.ros.refused_force_requests if self.ros else 0))
        return CallbackReturn.SUCCESS

    def on_activate(self, previous_state: State) -> CallbackReturn:
        """inactive -> active: commands start at the current pose, so stale commands never apply."""
        self._target = self.world.joint_positions()
        for handle, q in zip(self._pos_cmd, self._target, strict=True):
            handle.value = q
        return CallbackReturn.SUCCESS

    def on_cleanup(self, previous_state: State) -> CallbackReturn:
        """inactive -> unconfigured: camera thread stopped, publishers removed."""
        self._stop_io()
        return CallbackReturn.SUCCESS

    def on_shutdown(self, previous_state: State) -> CallbackReturn:
        self._stop_io()
        return CallbackReturn.SUCCESS

    def _stop_io(self) -> None:
        camera, self.camera = self.camera, None  # the loop thread sees None first
        ros, self.ros = self.ros, None
        if camera is not None:
            camera.stop()
        if ros is not None:
            ros.close()

    # ---- clock ------------------------------------------------------------------------------
    def now(self) -> float:
        return self.world.time_s

    # ---- real-time loop ---------------------------------------------------------------------
    def read(self, time: float, period: float) -> return_type:
        """Real-time loop (inactive and active): advance physics, copy states, publish at their rates."""
        world, camera, ros = self.world, self.camera, self.ros  # locals: shutdown may clear them
        while self._requests:
            try:
                self._requests.popleft()()
            except CommandError as error:   # validated by sim_ros already; never stop the loop
                self.get_logger().warning(f"{self.get_name()}: simulation request refused: {error}")
            except _InjectedError:
                self.get_logger().error(f"{self.get_name()}: injected hardware error (/sim/inject_hardware_error)")
                return return_type.ERROR
        answers = self.answers
        frame_due = world.time_s >= self._next_frame_s
        if self.paused:
            steps, self._steps_requested = self._steps_requested, 0
            self._wall_anchor = None   # realtime pacing restarts from here when resumed
        elif frame_due and answers is not None and answers.must_wait():
            steps = 0   # lock-step: the next frame waits for the answer to the last one
        else:
            steps = self._steps_for(period)
        start_s = world.time_s
        try:
            world.step(steps)
        except SimulationError as error:
            self.get_logger().error(f"{self.get_name()}: {error}")
            self._copy_states()
            return return_type.ERROR
        finally:
            self._resolve_steps((start_s, world.time_s))
        t = world.time_s
        if t >= self._next_push_s:
            self._next_push_s += world.knobs.push_interval_s
            angle = self._push_rng.uniform(0.0, 2.0 * math.pi)
            speed = world.knobs.push_speed_m_s
            self._push(speed * math.cos(angle), speed * math.sin(angle))
        if t >= self._next_force_change_s:
            self._step_forces(t)
        self._copy_states()
        # a camera frame (rendered, and/or a truth-fed detection), unless lock-step holds it back
        if t >= self._next_frame_s and not (answers is not None and answers.must_wait()):
            if answers is not None:
                answers.frame_captured(t)
            self._next_frame_s = max(self._next_frame_s + 1.0 / self.params["camera_rate_hz"], t)
            if camera is not None:
                snapshot = world.snapshot()
                if ros is not None:
                    ros.trace("capture", t)
                camera.submit(snapshot)
            if ros is not None and self.params["truth_fed"]:
                ros.publish_detection(t, *world.detected_ball())
        if ros is not None:
            if t >= self._next_truth_s:
                self._next_truth_s = max(self._next_truth_s + 1.0 / self.params["truth_rate_hz"], t)
                ros.publish_truth(world.ball_truth())
            if self.provides_clock and t >= self._next_clock_s:
                self._next_clock_s = max(self._next_clock_s + 1.0 / self.params["clock_rate_hz"], t)
                ros.publish_clock(t)
        return return_type.OK

    def _steps_for(self, period: float) -> int:
        dt = self.world.physics_dt_s
        if self.params["pacing"] == "realtime":
            wall = _time.monotonic()
            if self._wall_anchor is None:
                self._wall_anchor = (wall, self.world.time_s)
            behind = self._wall_anchor[1] + (wall - self._wall_anchor[0]) - self.world.time_s
            steps = int(behind / dt)
            if steps > int(0.05 / dt):  # more than 50 ms behind: do not spiral, re-anchor
                self.overruns += 1
                steps = int(0.05 / dt)
                self._wall_anchor = (wall, self.world.time_s + steps * dt)
                if wall - self._last_behind_warn > 5.0:
                    self._last_behind_warn = wall
                    self.get_logger().warning(
                        f"{self.get_name()}: pacing realtime fell {behind * 1e3:.0f} ms behind the wall clock "
                        f"({self.overruns} times so far); simulated time lags it from here. pacing: lockstep "
                        "slows simulated time instead, with the same outcome on any machine")
            return max(0, steps)
        if not (0.0 < period < 0.1):
            period = self.params["cycle_period"]
        return max(1, int(round(period / dt)))

    def _copy_states(self) -> None:
        world = self.world
        q, dq, tau = world.joint_positions(), world.joint_velocities(), world.joint_efforts()
        for i in range(6):
            self._pos[i].value = q[i]
            if self._vel[i] is not None:
                self._vel[i].value = dq[i]
            if self._eff[i] is not None:
                self._eff[i].value = tau[i]
        truth = world.ball_truth()
        for handle, value in zip(self._ball, (truth.x, truth.y, truth.vx, truth.vy, float(truth.dropped)),
                                 strict=True):
            handle.value = value
        if self._speed_scaling is not None:
            self._speed_scaling.value = world.speed_scaling
        ros = self.ros
        if ros is not None:
            ros.update_dropped(truth.dropped, truth)

    def write(self, time: float, period: float) -> return_type:
        """Real-time loop (active): position commands -> servo targets; bad ones refused and counted."""
        target = self._target.copy()
        given = False
        for i, handle in enumerate(self._pos_cmd):
            value = handle.value
            if value == value:  # NaN = no command yet: keep this joint's target
                target[i] = value
                given = True
        if not given:
            return return_type.OK
        try:
            self.world.set_joint_targets(target)
        except CommandError as error:
            self.commands_refused += 1
            if time - self._last_warn > 1.0:
                self._last_warn = time
                self.get_logger().warning(f"{self.get_name()}: refused joint command ({self.commands_refused} so "
                                          f"far): {error}")
            return return_type.OK
        if self.ros is not None and self.ros.trace_pub is not None and not np.array_equal(target, self._target):
            self.ros.trace("command", time)
        self._target = target
        return return_type.OK

    # ---- other threads ----------------------------------------------------------------------
    # Simulation requests (any thread; applied by the loop at its next read()). Each returns a
    # future the loop resolves when it has applied the request, with the simulated time then
    # (request_steps: the time before and after its steps).
    def _submit(self, action) -> Future:
        taken = Future()

        def run():
            try:
                action()
            except BaseException as error:
                taken.set_exception(error)
                raise
            taken.set_result(self.world.time_s)
        self._requests.append(run)
        return taken

    def request_reset_ball(self) -> Future:
        """Ball back to rest at the plate centre."""
        return self._submit(lambda: self.world.place_ball(0.0, 0.0))

    def request_reset_world(self) -> Future:
        """Arm at home at rest (servo targets too), ball at rest at (ball_x, ball_y)."""
        def reset():
            world = self.world
            world.set_joint_positions(robot.HOME_POSITIONS_RAD)
            world.place_ball(self.params["ball_x"], self.params["ball_y"])
            world.clear_forces()
            self._stepped_forces = []   # a domain's force step acting is cleared too
            self._next_force_change_s = self._next_force_change()
            self._hold_ball_force()   # a setting of the world, like the plate's mounting: it stays
            self._target = world.joint_positions()
            self._copy_states()
        return self._submit(reset)

    def request_hardware_error(self) -> Future:
        def fail():
            raise _InjectedError()
        return self._submit(fail)

    def request_pause(self, paused: bool) -> Future:
        """Stop (true) or resume (false) physics and the simulated clock."""
        def pause():
            self.paused = bool(paused)
            self._steps_requested = 0
            self._resolve_steps(None)   # steps asked for before a resume are not taken
        return self._submit(pause)

    def request_steps(self, steps: int) -> Future:
        """While paused: advance `steps` physics steps. The future's result is the (start, end)
        simulated times of the read() that took them, None if the loop was running when the
        request reached it or a resume came first."""
        taken = Future()

        def step():
            if not self.paused:   # a resume got in first: a running cycle is not these steps
                taken.set_result(None)
                return
            self._steps_requested += int(steps)
            self._steps_waiting.append(taken)
        self._requests.append(step)
        return taken

    def _resolve_steps(self, result) -> None:
        """(loop) Tell the step requests waiting what became of them."""
        while self._steps_waiting:
            self._steps_waiting.pop().set_result(result)

    def request_push(self, dv_m_s, in_plate_axes: bool = True) -> Future:
        """An impulse on the ball: velocity change (m/s; plate or world axes, its part along
        the plate taken), spin kept consistent with rolling."""
        def push():
            dv = np.asarray(dv_m_s, dtype=float)
            if not in_plate_axes:
                dv = self.world.plate_pose()[1].T @ dv
            self._push(float(dv[0]), float(dv[1]))
        return self._submit(push)

    def _push(self, dvx_m_s: float, dvy_m_s: float) -> None:
        """(loop) Apply a push and say so on /sim/ball_pushed."""
        self.world.push_ball(dvx_m_s, dvy_m_s)
        ros = self.ros
        if ros is not None:
            ros.publish_pushed(self.world.time_s, dvx_m_s, dvy_m_s)

    def request_ball_force(self, tilt_deg: float, direction_deg: float) -> Future:
        """A constant force on the ball's centre from the next read() on, replacing the last one:
        the force of a plate tilted by `tilt_deg` (F = m g sin(tilt), this domain's ball and
        gravity), towards `direction_deg` (plate axes, from +x). Raises ParameterError, naming
        the bad value, and changes nothing when a value is out of the bounds of
        ball_force_deg / ball_force_dir_deg."""
        tilt = _PARAMS["ball_force_deg"].validate(tilt_deg)
        direction = _PARAMS["ball_force_dir_deg"].validate(direction_deg)

        def hold():
            self.ball_force = (tilt, direction)
            self._hold_ball_force()
        return self._submit(hold)

    def ball_force_words(self, tilt_deg: float, direction_deg: float) -> str:
        """The force request_ball_force(tilt_deg, direction_deg) holds, in words."""
        f_n = math.hypot(*self.world.knobs.tilt_force_n(tilt_deg, 0.0))
        return (f"ball force {f_n * 1e3:.3f} mN towards {direction_deg:g} deg (plate axes), as a plate tilted "
                f"{tilt_deg:g} deg" if tilt_deg > 0.0 else "no ball force")

    def _hold_ball_force(self) -> None:
        """(loop, or before it runs) The world holds `ball_force` (tilt, direction) on the ball."""
        self.world.hold_force(*self.world.knobs.tilt_force_n(*self.ball_force))
        self._announce_force()

    def _next_force_change(self) -> float:
        """When the next force step of the domain begins or one acting ends (inf: none), so
        the loop compares one time per cycle."""
        times = [end_s for end_s, _, _ in self._stepped_forces]
        if self._force_steps:
            times.append(self._force_steps[0][0])
        return min(times, default=math.inf)

    def _step_forces(self, t: float) -> None:
        """(loop) The domain's force steps due by t begin, those past their end stop counting,
        and /sim/ball_force says what acts now (the world times each step itself)."""
        while self._force_steps and t >= self._force_steps[0][0]:
            start_s, duration_s, fx_n, fy_n = self._force_steps.popleft()
            self.world.apply_force(fx_n, fy_n, duration_s)
            self._stepped_forces.append((start_s + duration_s, fx_n, fy_n))
        self._stepped_forces = [step for step in self._stepped_forces if t < step[0]]
        self._next_force_change_s = self._next_force_change()
        self._announce_force()

    def _announce_force(self) -> None:
        """/sim/ball_force: the held force and the force steps acting, when that changed (a
        reset of the world holds the same force again), once the ROS side exists."""
        ros = self.ros
        if ros is None:
            return
        fx_n, fy_n = self.world.knobs.tilt_force_n(*self.ball_force)
        for _, step_fx_n, step_fy_n in self._stepped_forces:
            fx_n, fy_n = fx_n + step_fx_n, fy_n + step_fy_n
        if (fx_n, fy_n) != self._announced_force:
            self._announced_force = (fx_n, fy_n)
            ros.publish_force(self.world.time_s, fx_n, fy_n)

    def request_wrench(self, force_n, torque_n_m, duration_s: float, in_plate_axes: bool = True) -> Future:
        """A force and torque on the ball's centre for `duration_s` (plate or world axes)."""
        return self._submit(lambda: self.world.apply_wrench(force_n, torque_n_m, duration_s, in_plate_axes))

    def _on_frame(self, image, snapshot) -> None:
        ros = self.ros
        if ros is not None:
            ros.trace("rendered", snapshot.time_s)
            ros.publish_image(image, snapshot.time_s)

    def _on_camera_error(self, error: BaseException) -> None:
        self.get_logger().error(f"{self.get_name()}: camera stopped: {error}")


def check_description_params(urdf_text: str) -> None:
    """Validate the MuJoCo hardware params of a description without building the world
    (ParameterError / SimConfigError / RobotDescriptionError name the problem)."""
    robot.check_robot_description(urdf_text)
    build_sim(parse_hardware_params(robot.hardware_params(urdf_text)))


def main(argv=None) -> int:
    """`python -m ball_balance.hardware.mujoco_system --check FILE`: exit 2 with one line if bad."""
    import argparse
    import sys

    parser = argparse.ArgumentParser(description=check_description_params.__doc__)
    parser.add_argument("--check", required=True, metavar="URDF")
    args = parser.parse_args(argv)
    try:
        check_description_params(read_text_file(args.check, "robot description"))
    except (TextFileError, ParameterError, SimConfigError, robot.RobotDescriptionError) as error:
        print(f"ball_balance/MujocoSystem: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
