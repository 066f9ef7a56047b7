"""`robot_manager`: the lifecycle node that says when the arm may move, and the emergency stop.

States (lifecycle_msgs; reference in docs/robot_manager.md):
  unconfigured  start-up: the controller manager has loaded the hardware and the controllers,
                and nothing that moves the arm is active.
  configure     hardware configured (inactive), camera frames arriving, intrinsics received,
                markers seen and the plate pose fitted, the controllers configured; fails with
                one reason naming what is missing.
  activate      hardware active and the balancing controllers activated (one strict switch);
                refused while the emergency stop is latched.
  deactivate    the plate levels along a smooth path, then the controllers stop and the
                hardware goes inactive.
  cleanup       hardware unconfigured. shutdown: controllers stopped, hardware inactive.

Emergency stop: ~/emergency_stop (std_srvs/Trigger), and the watchdogs (a hardware component
or a balancing controller that left `active`, no heartbeat from the controller manager, no
camera frame while the ball is on the plate) call `trigger_emergency_stop(reason, source)`:
every commanding controller is deactivated in one switch, the hardware goes inactive (it
holds its last target), the latch is set (~/emergency_stop_active, Bool, transient local) and
the node ends up inactive. It stays so until ~/reset_emergency_stop, which clears the latch
and moves nothing.
Every stop and transition is an event on ~/events (diagnostic_msgs/DiagnosticStatus, name
robot_manager, values event/source/lifecycle_state) and a status on /diagnostics.

Executor: one single-threaded executor. The lifecycle services are this node's own async
callbacks (the rclpy LifecycleNode runs with its communication interface off): each awaits its
calls to the controller manager with a deadline (manager_client.py), then commits the
transition through LifecycleNode.trigger_*(), whose hooks only check the prepared result.
"""
from __future__ import annotations

import math
import time

from ball_tracker_msgs.msg import BallState
from controller_manager_msgs.msg import ControllerManagerActivity
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseWithCovarianceStamped
from lifecycle_msgs import msg as lc_msg
from lifecycle_msgs import srv as lc_srv
from pal_statistics_msgs.msg import StatisticsValues
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Bool, Float64MultiArray
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ball_balance import robot
from ball_balance.nodes.manager_client import BEST_EFFORT, STRICT, ManagerCallError, ManagerClient, names, sleep
from ball_balance.operation import lifecycle as lc
from ball_balance.operation.levelling import levelling_duration, levelling_path
from ball_balance.operation.watchdog import Watchdog, WatchdogLimits
from controller_manager_py.parameters import Param, declare_parameters
from controller_manager_py.ros.node_main import main_for

_NONE = [""]
SCHEMA = (
    Param("autostart", False, "configure and activate at start-up (the outcome is logged and published as events)",
          user_facing=True),
    Param("controller_manager", "/controller_manager", "the controller manager's node name", user_facing=True),
    Param("controllers", ["forward_position_controller"],
          "the balancing controllers, activated with the hardware; one that leaves active while the robot "
          "manager is active is an emergency stop", user_facing=True),
    Param("stop_controllers", ["forward_position_controller", "scaled_joint_trajectory_controller",
                               "ball_balance_controller"],
          "controllers a stop deactivates (those loaded and active; with `controllers` and `level_controller`)"),
    Param("hardware_components", _NONE, "hardware components managed (empty: every component of the manager)"),
    Param("level_controller", "scaled_joint_trajectory_controller",
          "controller that levels the plate at deactivate: a joint trajectory controller (one trajectory) or a "
          "forward position controller (positions streamed); empty: no levelling", user_facing=True),
    Param("level_positions", list(robot.HOME_POSITIONS_RAD), "joint positions of the level plate", unit="rad",
          check=lambda q: None if len(q) == len(robot.HOME_POSITIONS_RAD) else
          f"must hold {len(robot.HOME_POSITIONS_RAD)} positions, one per arm joint"),
    Param("level_min_duration_s", 2.0, "shortest levelling motion", unit="s", min=0.1, max=60.0),
    Param("level_tolerance_rad", 1e-3, "deactivate waits until every joint is this close to level_positions",
          unit="rad", min=1e-5, max=0.5),
    Param("level_max_speed_rad_s", 0.3, "fastest joint speed of the levelling motion", unit="rad/s",
          min=0.01, max=3.0),
    Param("camera_required", True, "configure needs camera frames, intrinsics and a plate pose (false: a graph "
          "without a camera, e.g. the truth-fed simulation, or one paused until activation); the camera-lost "
          "watchdog runs whenever frames have arrived", user_facing=True),
    Param("image_topic", "/camera/image_raw", "camera frames (sensor data QoS)"),
    Param("camera_info_topic", "/camera/camera_info", "camera intrinsics (sensor data QoS)"),
    Param("ball_state_topic", "/ball_state", "the tracker's output"),
    Param("plate_pose_topic", "/plate_pose", "the tracker's plate fit"),
    Param("configure_timeout_s", 5.0, "how long configure waits for the camera, the intrinsics and the plate pose",
          unit="s", min=0.1, max=600.0, user_facing=True),
    Param("manager_wait_s", 30.0, "how long configure waits for the controller manager's services", unit="s",
          min=0.1, max=600.0),
    Param("service_timeout_s", 10.0, "deadline of each call to the controller manager", unit="s", min=0.1, max=120.0),
    Param("manager_timeout_s", 3.0, "stop when the controller manager's statistics stop this long (stalled)",
          unit="s", min=0.1, max=60.0, user_facing=True),
    Param("camera_lost_timeout_s", 3.0, "stop when no camera frame comes this long while the ball is on the plate",
          unit="s", min=0.1, max=60.0, user_facing=True),
    Param("watchdog_period_s", 0.05, "period of the watchdog checks", unit="s", min=0.005, max=1.0),
)

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
EVENTS_QOS = QoSProfile(depth=20, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
OK, WARN, ERROR = 0, 1, 2
HW_IDS = {"unconfigured": lc.UNCONFIGURED, "inactive": lc.INACTIVE, "active": lc.ACTIVE}


class RobotManagerNode(LifecycleNode):
    def __init__(self, node_name: str = "robot_manager", **node_kwargs):
        super().__init__(node_name, enable_communication_interface=False, **node_kwargs)
        self.params = p = declare_parameters(self, SCHEMA)
        self.steady = Clock(clock_type=ClockType.STEADY_TIME)
        # reentrant: a transition awaiting the controller manager must not hold back the other
        # callbacks (the default mutually exclusive group would: its timers included, a deadlock)
        self.group = group = ReentrantCallbackGroup()
        self.state = lc.UNCONFIGURED
        self.busy = ""                 # the transition being prepared ('' when none)
        self.busy_state = lc.UNKNOWN   # its transition state (get_state answers it meanwhile, as rcl does)
        self._prepared = None          # None: not prepared; '' success; text: the failure
        self.estop = False
        self.estop_reason = ""
        self._stop_confirmed = True
        self._stop_task = None
        self._last_stop_try = -math.inf
        self.cm = ManagerClient(self, p["controller_manager"], p["service_timeout_s"], group)
        self.watchdog = Watchdog(WatchdogLimits(p["manager_timeout_s"], p["camera_lost_timeout_s"]),
                                 heartbeat_topic=f"{self.cm.manager}/statistics/values", camera_topic=p["image_topic"])
        self.controller_states = {}    # name -> label, from the manager's ~/activity
        self.last_info = None
        self.last_pose_fit_s = None
        self.last_ball = None          # (monotonic s, BallState)
        self.joint_state = None
        # what the manager and the camera say
        sub, srv = self._subscribe, self._serve
        sub(ControllerManagerActivity, f"{self.cm.manager}/activity", self.on_activity, LATCHED)
        sub(StatisticsValues, self.watchdog.heartbeat_topic, self.on_heartbeat, 10)
        sub(Image, p["image_topic"], self.on_image, QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT),
            raw=True)
        sub(CameraInfo, p["camera_info_topic"], self.on_camera_info, qos_profile_sensor_data)
        sub(BallState, p["ball_state_topic"], self.on_ball_state, qos_profile_sensor_data)
        sub(PoseWithCovarianceStamped, p["plate_pose_topic"], self.on_plate_pose, qos_profile_sensor_data)
        # what it says
        self.estop_pub = self.create_publisher(Bool, "~/emergency_stop_active", LATCHED)
        self.events_pub = self.create_publisher(DiagnosticStatus, "~/events", EVENTS_QOS)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.transition_pub = self.create_publisher(lc_msg.TransitionEvent, "~/transition_event", 10)
        self.level_traj_pub = self.level_fwd_pub = None
        level = p["level_controller"]
        if level:
            self.level_traj_pub = self.create_publisher(JointTrajectory, f"/{level}/joint_trajectory", 10)
            self.level_fwd_pub = self.create_publisher(Float64MultiArray, f"/{level}/commands", 10)
        # lifecycle_msgs services, as rcl_lifecycle names them
        srv(lc_srv.ChangeState, "~/change_state", self.on_change_state)
        srv(lc_srv.GetState, "~/get_state", self.on_get_state)
        srv(lc_srv.GetAvailableStates, "~/get_available_states", self.on_get_available_states)
        srv(lc_srv.GetAvailableTransitions, "~/get_available_transitions", self.on_get_available_transitions)
        srv(lc_srv.GetAvailableTransitions, "~/get_transition_graph", self.on_get_transition_graph)
        srv(Trigger, "~/emergency_stop", self.on_emergency_stop)
        srv(Trigger, "~/reset_emergency_stop", self.on_reset_emergency_stop)
        self.estop_pub.publish(Bool(data=False))
        self.create_timer(p["watchdog_period_s"], self.on_watchdog, group, clock=self.steady)
        self.create_timer(1.0, self.publish_diagnostics, group, clock=self.steady)
        self._autostart_timer = (self.create_timer(0.1, self.on_autostart, group, clock=self.steady)
                                 if p["autostart"] else None)

    def announce(self) -> None:
        """The start-up line (controller_manager_py.ros.node_main.run_node)."""
        p = self.params
        self.get_logger().info(f"unconfigured; controllers {names(p['controllers'])}, controller manager "
                               f"{self.cm.manager}{'; autostart' if p['autostart'] else ''}")

    def _subscribe(self, msg_type, topic, callback, qos, raw=False):
        return self.create_subscription(msg_type, topic, callback, qos, callback_group=self.group, raw=raw)

    def _serve(self, srv_type, name, callback):
        return self.create_service(srv_type, name, callback, callback_group=self.group)

    # ---- public API (services and watchdogs call these) ---------------------------------------
    @property
    def state_label(self) -> str:
        return lc.STATE_LABELS[self.state]

    async def change_state(self, label: str = "", transition_id: int = 0, source: str = "service"):
        """Run one transition: (success, reason). Refused while another one runs."""
        try:
            transition = lc.resolve(self.state, transition_id, label)
        except lc.LifecycleError as error:
            return False, str(error)
        if self.busy:
            return False, f"{self.busy} is in progress"
        self.busy, self.busy_state = transition.label, transition.via
        start = self.state
        try:
            self._publish_transition(transition, start, transition.via)
            try:
                reason = await getattr(self, f"_prepare_{transition.label}")()
            except ManagerCallError as error:
                reason = str(error)
            except Exception as error:  # noqa: BLE001 - a bug fails the transition, not the node
                reason = f"internal error: {error!r}"
            self._prepared = reason or ""
            result = self._commit(transition)
            self.state = lc.outcome(transition, result, lc.SUCCESS)
            self._publish_transition(transition, transition.via, self.state)
        finally:
            self._prepared = None
            self.busy = ""
        ok = result == lc.SUCCESS
        text = (f"{transition.label}: {lc.STATE_LABELS[start]} -> {self.state_label}" if ok
                else f"{transition.label} failed: {reason}")
        if ok:
            self.get_logger().info(text)
        else:
            self.get_logger().error(text)
        self.publish_event(OK if ok else WARN, "state_change" if ok else "transition_failed", source, text)
        return ok, "" if ok else reason

    def trigger_emergency_stop(self, reason: str, source: str = "service") -> None:
        """Latch the stop and stop the arm (at once, from any callback; the stopping itself is a
        task on the executor). Further calls while latched only repeat the stop."""
        if not self.estop:
            self.estop, self.estop_reason = True, reason
            self.estop_pub.publish(Bool(data=True))
            self.get_logger().error(f"emergency stop ({source}): {reason}")
            self.publish_event(ERROR, "emergency_stop", source, reason)
        self._start_stop()

    def reset_emergency_stop(self):
        """(success, message). Clears the latch; moves nothing (activate again to resume)."""
        if not self.estop:
            return True, "no emergency stop was latched"
        if not self._stop_confirmed:
            return False, "the stop is not confirmed by the controller manager yet; reset refused"
        self.estop, self.estop_reason = False, ""
        self.estop_pub.publish(Bool(data=False))
        message = f"emergency stop reset; the robot manager is {self.state_label} (activate to resume)"
        self.get_logger().info(message)
        self.publish_event(OK, "reset", "service", message)
        return True, message

    # ---- lifecycle hooks (run inside trigger_*: they only check the prepared result) ----------
    def _hook(self, what: str) -> TransitionCallbackReturn:
        if self._prepared is None:
            self.get_logger().error(f"{what}: use the ~/change_state service (or change_state()) to change state")
            return TransitionCallbackReturn.FAILURE
        return TransitionCallbackReturn.FAILURE if self._prepared else TransitionCallbackReturn.SUCCESS

    def on_configure(self, state):
        return self._hook("configure")

    def on_activate(self, state):
        return self._hook("activate")

    def on_deactivate(self, state):
        return self._hook("deactivate")

    def on_cleanup(self, state):
        return self._hook("cleanup")

    def on_shutdown(self, state):
        return self._hook("shutdown")

    def on_error(self, state):
        return TransitionCallbackReturn.SUCCESS

    def _commit(self, transition: lc.Transition) -> str:
        trigger = {"configure": self.trigger_configure, "activate": self.trigger_activate,
                   "deactivate": self.trigger_deactivate, "cleanup": self.trigger_cleanup,
                   "shutdown": self.trigger_shutdown}[transition.label]
        result = trigger()
        return {TransitionCallbackReturn.SUCCESS: lc.SUCCESS,
                TransitionCallbackReturn.FAILURE: lc.FAILURE}.get(result, lc.ERROR)

    # ---- what each transition does (awaited; None or '' = ready, else the one reason) ---------
    async def _prepare_configure(self):
        p = self.params
        deadline = time.monotonic() + p["manager_wait_s"]
        while not self.cm.ready():
            if time.monotonic() > deadline:
                return (f"no controller manager: its services under {self.cm.manager} did not appear within "
                        f"{p['manager_wait_s']:g} s")
            await sleep(self, 0.1, self.group)
        hardware = await self._managed_hardware()
        for name, state in hardware.items():
            if state == "unconfigured":
                await self.cm.set_hardware_state(name, lc.INACTIVE, "inactive")
            elif state not in ("inactive", "active"):
                return f"hardware '{name}' is {state}; it cannot be configured"
        if p["camera_required"]:
            reason = await self._wait_for_camera()
            if reason:
                return reason
        controllers = await self.cm.controllers()
        for name in self._needed_controllers():
            if name not in controllers:
                return f"controller '{name}' is not loaded in {self.cm.manager}"
            if controllers[name].state == "unconfigured":
                await self.cm.configure_controller(name)
            elif controllers[name].state == "active":
                return f"controller '{name}' is already active (something else activated it)"
        return None

    async def _wait_for_camera(self):
        p = self.params
        start = time.monotonic()
        wait_s = p["configure_timeout_s"]

        def fresh(t):
            return t is not None and t >= start - wait_s

        def missing():
            if not fresh(self.watchdog.last_frame_s):
                return f"no camera frames on {p['image_topic']} for {wait_s:g} s"
            if self.last_info is None or not any(self.last_info.k):
                return f"no camera intrinsics on {p['camera_info_topic']} for {wait_s:g} s"
            if self.last_ball is None or not fresh(self.last_ball[0]):
                return f"no {p['ball_state_topic']} from the tracker for {wait_s:g} s"
            if not fresh(self.last_pose_fit_s):
                return (f"markers not seen: no plate pose fitted on {p['plate_pose_topic']} for {wait_s:g} s "
                        f"(the last {p['ball_state_topic']} saw {self.last_ball[1].markers_found} of 4 markers)")
            return None
        while (reason := missing()) is not None and time.monotonic() - start < wait_s:
            await sleep(self, 0.05, self.group)
        return reason

    async def _prepare_activate(self):
        if self.estop:
            return f"the emergency stop is latched ({self.estop_reason}); reset it first"
        hardware = await self._managed_hardware()
        for name, state in hardware.items():
            if state == "inactive":
                await self.cm.set_hardware_state(name, lc.ACTIVE, "active")
            elif state != "active":
                return f"hardware '{name}' is {state}, not inactive"
        self.watchdog.forget_controllers()
        try:
            await self.cm.switch(activate=names(self.params["controllers"]), strictness=STRICT)
        except ManagerCallError as error:
            await self._hardware_to("inactive", ("active",))
            return str(error)
        if self.estop:   # stopped while activating: the stop task undoes it
            return f"emergency stop during activation ({self.estop_reason})"
        self.watchdog.arm(time.monotonic())
        return None

    async def _prepare_deactivate(self):
        if not self.estop:
            await self._level_plate()
        await self._stop_commanding()
        return None

    async def _prepare_cleanup(self):
        await self._hardware_to("unconfigured", ("inactive",))
        return None

    async def _prepare_shutdown(self):
        if self.state == lc.ACTIVE:
            await self._stop_commanding()
        return None

    # ---- the pieces -------------------------------------------------------------------------
    def _needed_controllers(self):
        p = self.params
        return [*names(p["controllers"]), *([p["level_controller"]] if p["level_controller"] else [])]

    async def _managed_hardware(self) -> dict:
        hardware = await self.cm.hardware()
        wanted = names(self.params["hardware_components"])
        missing = [n for n in wanted if n not in hardware]
        if missing:
            raise ManagerCallError(f"hardware {missing} is not loaded in {self.cm.manager} (it has {list(hardware)})")
        chosen = {n: s for n, s in hardware.items() if not wanted or n in wanted}
        self.watchdog.hardware = {}   # the watchdog learns them again from ~/activity
        return chosen

    async def _hardware_to(self, label: str, from_states) -> None:
        for name, state in (await self._managed_hardware()).items():
            if state in from_states:
                await self.cm.set_hardware_state(name, HW_IDS[label], label)

    def _stoppable(self):
        p = self.params
        wanted = dict.fromkeys([*names(p["stop_controllers"]), *self._needed_controllers()])
        if not self.controller_states:
            return list(wanted)
        return [n for n in wanted if self.controller_states.get(n) == "active"]

    async def _stop_commanding(self) -> None:
        """Every commanding controller deactivated (one switch), then the hardware inactive."""
        stoppable = self._stoppable()
        if stoppable:
            await self.cm.switch(deactivate=stoppable, strictness=BEST_EFFORT)
        await self._hardware_to("inactive", ("active",))

    async def _level_plate(self) -> None:
        """Balancing controllers off, the level controller on, a smooth path to level_positions."""
        p = self.params
        level = p["level_controller"]
        if not level:
            return
        balancing = [n for n in names(p["controllers"]) if n != level]
        await self.cm.switch(activate=[] if level in names(p["controllers"]) else [level],
                             deactivate=balancing, strictness=STRICT)
        # where the level controller holds the arm now (the balancing moved it until the switch)
        current = await self._joint_positions()
        if current is None:
            self.get_logger().warning("deactivate: no /joint_states within 5 s; the plate is not levelled")
            return
        target = list(p["level_positions"])
        duration = levelling_duration(current, target, p["level_max_speed_rad_s"], p["level_min_duration_s"])
        controller = (await self.cm.controllers()).get(level)
        if controller is not None and controller.type.startswith("joint_trajectory_controller"):
            msg = JointTrajectory(joint_names=list(robot.JOINT_NAMES))
            for t, q in levelling_path(current, target, duration, 50):
                msg.points.append(JointTrajectoryPoint(positions=q, time_from_start=_duration(t)))
            self.level_traj_pub.publish(msg)
        else:   # a forward position controller: the path streamed at 50 Hz
            start = time.monotonic()
            for t, q in levelling_path(current, target, duration, max(2, int(duration * 50))):
                if self.estop:
                    break
                await sleep(self, max(0.001, start + t - time.monotonic()), self.group)
                self.level_fwd_pub.publish(Float64MultiArray(data=q))
        # arrived (on a loaded machine simulated time may run slower than the wall clock)
        tolerance = p["level_tolerance_rad"]
        reached = await self._joint_positions(
            lambda q: max(abs(a - b) for a, b in zip(q, target, strict=True)) < tolerance,
            timeout_s=5.0 * duration + 10.0)
        if self.estop:
            self.get_logger().warning("deactivate: levelling interrupted by the emergency stop")
        elif reached is None:
            self.get_logger().warning(f"deactivate: the plate did not reach level within {5.0 * duration + 10.0:.0f} s")
        else:
            self.get_logger().info(f"deactivate: plate levelled ({duration:.1f} s path)")

    async def _joint_positions(self, until=lambda q: True, timeout_s: float = 5.0):
        """The arm's joint positions from /joint_states once `until(positions)` holds (None after
        timeout_s of wall time, or at an emergency stop)."""
        self.joint_state = None
        sub = self._subscribe(JointState, "/joint_states", self.on_joint_states, 10)
        try:
            end = time.monotonic() + timeout_s
            while time.monotonic() < end and not (self.estop and self.busy == "deactivate"):
                msg = self.joint_state
                if msg is not None:
                    index = {n: i for i, n in enumerate(msg.name)}
                    q = [msg.position[index[n]] for n in robot.JOINT_NAMES]
                    if until(q):
                        return q
                await sleep(self, 0.02, self.group)
        finally:
            self.destroy_subscription(sub)
        return None

    # ---- emergency stop ---------------------------------------------------------------------
    def _start_stop(self) -> None:
        if self._stop_task is not None and not self._stop_task.done():
            return
        self._stop_confirmed = False
        self._last_stop_try = time.monotonic()
        self._stop_task = self.executor.create_task(self._stop())

    async def _stop(self) -> None:
        try:
            await self._stop_commanding()
        except Exception as error:  # noqa: BLE001 - ManagerCallError, or a bug: the watchdog tries again
            self.get_logger().error(f"emergency stop: {error}; trying again")
            return
        self._stop_confirmed = True
        self.get_logger().warning("emergency stop: controllers deactivated, hardware inactive (holding)")
        if self.state == lc.ACTIVE and not self.busy:
            await self.change_state("deactivate", source="emergency_stop")

    async def on_emergency_stop(self, request, response):
        self.trigger_emergency_stop("emergency stop requested (service)", "service")
        deadline = time.monotonic() + self.params["service_timeout_s"]
        while not self._stop_confirmed and time.monotonic() < deadline:
            await sleep(self, 0.005, self.group)
        response.success = True
        response.message = ("stopped: controllers deactivated, hardware holding; latched until reset"
                            if self._stop_confirmed else
                            "latched; the controller manager has not confirmed the stop yet (retrying)")
        return response

    def on_reset_emergency_stop(self, request, response):
        response.success, response.message = self.reset_emergency_stop()
        return response

    # ---- lifecycle_msgs services --------------------------------------------------------------
    async def on_change_state(self, request, response):
        response.success, _ = await self.change_state(request.transition.label, request.transition.id)
        return response

    def on_get_state(self, request, response):
        state = self.busy_state if self.busy else self.state
        response.current_state = lc_msg.State(id=state, label=lc.STATE_LABELS[state])
        return response

    def on_get_available_states(self, request, response):
        response.available_states = [lc_msg.State(id=i, label=label) for i, label in lc.STATE_LABELS.items()]
        return response

    def on_get_available_transitions(self, request, response):
        response.available_transitions = [_description(t) for t in lc.available(self.state)]
        return response

    def on_get_transition_graph(self, request, response):
        response.available_transitions = [_description(t) for t in lc.TRANSITIONS]
        return response

    # ---- inputs -----------------------------------------------------------------------------
    def on_activity(self, msg) -> None:
        self.controller_states = {c.name: c.state.label for c in msg.controllers}
        balancing = names(self.params["controllers"])
        self.watchdog.watch_controllers({n: s for n, s in self.controller_states.items() if n in balancing})
        wanted = names(self.params["hardware_components"])
        self.watchdog.hardware = {c.name: c.state.label for c in msg.hardware_components
                                  if not wanted or c.name in wanted}

    def on_heartbeat(self, msg) -> None:
        self.watchdog.last_heartbeat_s = time.monotonic()

    def on_image(self, raw) -> None:
        self.watchdog.last_frame_s = time.monotonic()

    def on_camera_info(self, msg) -> None:
        self.last_info = msg

    def on_ball_state(self, msg) -> None:
        self.last_ball = (time.monotonic(), msg)
        self.watchdog.ball_on_plate = bool(msg.tracking_valid)

    def on_plate_pose(self, msg) -> None:
        if math.isfinite(msg.pose.covariance[0]):
            self.last_pose_fit_s = time.monotonic()

    def on_joint_states(self, msg) -> None:
        self.joint_state = msg

    # ---- timers -----------------------------------------------------------------------------
    def on_watchdog(self) -> None:
        now = time.monotonic()
        if self.estop and not self._stop_confirmed and now - self._last_stop_try > 1.0:
            self._start_stop()   # the manager did not confirm: again, until it does
        if self.state != lc.ACTIVE or self.estop:
            return
        problem = self.watchdog.check(now)
        if problem is not None and self.busy and problem[0] != "manager_stalled":
            return   # our own transition changes the hardware and the controllers
        if problem is not None:
            source, reason = problem
            self.trigger_emergency_stop(reason, source)

    def on_autostart(self) -> None:
        self._autostart_timer.cancel()
        self.executor.create_task(self._autostart())

    async def _autostart(self) -> None:
        for label in ("configure", "activate"):
            ok, reason = await self.change_state(label, source="autostart")
            if not ok:
                self.get_logger().error(f"autostart: {label} failed: {reason}")
                return
        self.get_logger().info("autostart: active")

    # ---- output -----------------------------------------------------------------------------
    def _status(self, level: int, message: str, values) -> DiagnosticStatus:
        return DiagnosticStatus(level=bytes([level]), name="robot_manager", message=message,
                                hardware_id=self.get_fully_qualified_name(),
                                values=[KeyValue(key=k, value=v) for k, v in values])

    def publish_event(self, level: int, event: str, source: str, message: str) -> None:
        status = self._status(level, message, (("event", event), ("source", source),
                                               ("lifecycle_state", self.state_label)))
        self.events_pub.publish(status)
        if level == ERROR:
            self.diagnostics_pub.publish(DiagnosticArray(header=self._header(), status=[status]))

    def publish_diagnostics(self) -> None:
        if self.estop:
            status = self._status(ERROR, f"emergency stop latched: {self.estop_reason}",
                                  (("lifecycle_state", self.state_label), ("emergency_stop", "true")))
        else:
            status = self._status(OK, self.state_label, (("lifecycle_state", self.state_label),
                                                         ("emergency_stop", "false")))
        self.diagnostics_pub.publish(DiagnosticArray(header=self._header(), status=[status]))

    def _header(self):
        from std_msgs.msg import Header
        return Header(stamp=self.get_clock().now().to_msg())

    def _publish_transition(self, transition: lc.Transition, start: int, goal: int) -> None:
        self.transition_pub.publish(lc_msg.TransitionEvent(
            timestamp=self.get_clock().now().nanoseconds,
            transition=lc_msg.Transition(id=transition.id, label=transition.label),
            start_state=lc_msg.State(id=start, label=lc.STATE_LABELS[start]),
            goal_state=lc_msg.State(id=goal, label=lc.STATE_LABELS[goal])))


def _description(t: lc.Transition) -> lc_msg.TransitionDescription:
    return lc_msg.TransitionDescription(
        transition=lc_msg.Transition(id=t.id, label=t.label),
        start_state=lc_msg.State(id=t.start, label=lc.STATE_LABELS[t.start]),
        goal_state=lc_msg.State(id=t.via, label=lc.STATE_LABELS[t.via]))


def _duration(seconds: float):
    from builtin_interfaces.msg import Duration
    return Duration(sec=int(seconds), nanosec=int(round((seconds % 1) * 1e9)) % 1_000_000_000)


main = main_for(RobotManagerNode)

if __name__ == "__main__":
    main()
