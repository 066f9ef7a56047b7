"""The robot manager on the simulated graph (real processes over DDS): the MuJoCo arm started
for it (scripts/sim_arm.sh --managed: hardware inactive, only joint_state_broadcaster active),
the PID balance node, and robot_manager. /ball_state comes from the simulation's true ball plus
noise (truth-fed: no camera and tracker, so a busy machine does not starve them); a second
robot manager that requires the camera shows configure failing with its reason.

One graph serves the whole file (it takes a while to start); the tests run in file order,
and the hardware error, which leaves the simulated hardware unconfigured, comes last. Times
of motion are judged on the /joint_states stamps (simulated time, the one time base of the
graph); "the call" is the newest /clock received before the request left.
"""
import os
import re
import signal
import time

import numpy as np
import pytest
from controller_manager_msgs.srv import ListControllers
from diagnostic_msgs.msg import DiagnosticStatus
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool
from std_srvs.srv import Trigger

from ball_balance import robot
from harness import ROOT, DomainLease, Graph, Launcher, executable

pytestmark = [pytest.mark.integration, pytest.mark.timeout(600)]
LATCHED = QoSProfile(depth=20, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
START_TIMEOUT = 180.0    # MuJoCo, the manager and its controllers in new processes on a loaded machine
CALL_TIMEOUT = 60.0
STILL_RAD_S = 1e-3
HOME = np.array(robot.HOME_POSITIONS_RAD)


class Rig:
    """The shared graph and the test's view of it."""

    def __init__(self, tmp_path):
        self.lease = DomainLease()
        self.launcher = Launcher(self.lease.domain_id, tmp_path)
        self.graph = Graph(self.lease.domain_id)
        self.events, self.latch, self.states = [], [], []
        node = self.graph.node
        node.create_subscription(DiagnosticStatus, "/robot_manager/events", self.events.append, LATCHED)
        node.create_subscription(Bool, "/robot_manager/emergency_stop_active", lambda m: self.latch.append(m.data),
                                 LATCHED)
        node.create_subscription(JointState, "/joint_states", self.states.append, 1000)
        # the newest simulated time only (depth 1): a history queue may lag behind while the test
        # process works through it
        self.clock = []
        node.create_subscription(Clock, "/clock", lambda m: self.clock.append(m.clock.sec + m.clock.nanosec * 1e-9), 1)
        self.latest = []   # the newest /joint_states (depth 1), for "now"-conditions
        node.create_subscription(JointState, "/joint_states", self._keep_latest, 1)
        self.sim = self.launcher.start([str(ROOT / "scripts" / "sim_arm.sh"), "--managed", "--sim-config",
                                        str(ROOT / "config" / "sim_truth_fed.yaml"), "--param", "ball_x=0.05",
                                        "--param", "ball_y=-0.03"], name="sim")
        pid_yaml = str(ROOT / "config" / "pid.yaml")
        self.launcher.start(["ball_balance_controller", "--ros-args", "--params-file", pid_yaml,
                             "-p", "use_sim_time:=true", "-p", "joint_states_timeout_s:=5.0"], name="controller")
        self.manager = self.launcher.start([executable("robot_manager"), "--ros-args", "-p", "camera_required:=false",
                                            "-p", "level_min_duration_s:=1.0"], name="robot_manager")
        self.camera_check = self.launcher.start(
            [executable("robot_manager"), "--ros-args", "-r", "__node:=camera_check", "-p", "level_controller:=''",
             "-p", "configure_timeout_s:=2.0"], name="camera_check")

    def _keep_latest(self, msg):
        self.latest[:] = [msg]

    def close(self):
        self.launcher.stop_all()
        self.graph.close()
        self.lease.release()

    # ---- helpers ------------------------------------------------------------------------------
    def transition(self, label: str, node: str = "/robot_manager") -> bool:
        request = ChangeState.Request(transition=Transition(label=label))
        return self.graph.call(ChangeState, f"{node}/change_state", request, timeout=CALL_TIMEOUT).success

    def state(self, node: str = "/robot_manager") -> str:
        response = self.graph.call(GetState, f"{node}/get_state", GetState.Request(), timeout=CALL_TIMEOUT)
        return response.current_state.label

    def trigger(self, service: str):
        return self.graph.call(Trigger, service, Trigger.Request(), timeout=CALL_TIMEOUT)

    def trigger_at(self, service: str):
        """Call `service` (std_srvs/Trigger) through a client already matched with it: (the
        simulated time when the request left, the response)."""
        client = self.graph.node.create_client(Trigger, service)
        try:
            self.graph.spin_until(client.service_is_ready, CALL_TIMEOUT, f"service {service}")
            self.graph.spin_for(0.5)   # the server has matched this client too
            t_call = self.now()
            future = client.call_async(Trigger.Request())
            self.graph.spin_until(future.done, CALL_TIMEOUT, f"response from {service}")
            return t_call, future.result()
        finally:
            self.graph.node.destroy_client(client)

    def controllers(self) -> dict:
        response = self.graph.call(ListControllers, "/controller_manager/list_controllers", ListControllers.Request(),
                                   timeout=CALL_TIMEOUT)
        return {c.name: c.state for c in response.controller}

    def now(self) -> float:
        """The simulated time now: a /clock that arrived after this call began."""
        seen = len(self.clock)
        self.graph.spin_until(lambda: len(self.clock) > seen + 1, 60, "/clock")
        return self.clock[-1]

    def samples_between(self, t0: float, t1: float):
        """The /joint_states stamped in [t0, t1], waiting until one past t1 has arrived."""
        self.graph.spin_until(lambda: self.states and stamp(self.states[-1]) > t1, 120,
                              f"/joint_states past {t1:.2f} s")
        return [m for m in self.states if t0 <= stamp(m) <= t1]

    def wait_for_event(self, predicate, what: str, timeout: float = 60.0) -> DiagnosticStatus:
        found = []
        self.graph.spin_until(lambda: found.extend(e for e in self.events if predicate(e)) or found, timeout, what)
        return found[0]

    def ensure_active(self):
        if self.latch and self.latch[-1]:
            assert self.trigger("/robot_manager/reset_emergency_stop").success
        if self.state() == "unconfigured":
            assert self.transition("configure"), self.manager.output()[-2000:]
        if self.state() == "inactive":
            assert self.transition("activate"), self.manager.output()[-2000:]
        assert self.state() == "active"

    def wait_until_moving(self):
        """Until the balance controller tilts the plate (the ball was released off centre)."""
        self.graph.spin_until(lambda: self.latest and (speed(self.latest[-1]) > 0.01 or
                                                       np.abs(positions(self.latest[-1]) - HOME).max() > 2e-3),
                              60, "the arm moving")


def stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def positions(msg) -> np.ndarray:
    index = {n: i for i, n in enumerate(msg.name)}
    return np.array([msg.position[index[n]] for n in robot.JOINT_NAMES])


def speed(msg) -> float:
    index = {n: i for i, n in enumerate(msg.name)}
    return max(abs(msg.velocity[index[n]]) for n in robot.JOINT_NAMES)


def value(event: DiagnosticStatus, key: str) -> str:
    return next((kv.value for kv in event.values if kv.key == key), "")


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    rig = Rig(tmp_path_factory.mktemp("robot_manager"))
    try:
        rig.graph.spin_until(lambda: rig.states, START_TIMEOUT, "/joint_states from the simulated arm")
        rig.graph.wait_for_service("/robot_manager/change_state", 60)
        yield rig
    finally:
        rig.close()


def test_nothing_moves_before_activate(rig):
    assert rig.state() == "unconfigured"
    assert rig.controllers()["forward_position_controller"] == "inactive"
    t0 = rig.now()
    # the PID node sees the ball off centre and commands from the start: nothing may follow
    for message in rig.samples_between(t0, t0 + 1.0):
        assert speed(message) < STILL_RAD_S and np.abs(positions(message) - HOME).max() < 1e-4
    assert rig.transition("configure"), rig.manager.output()[-2000:]
    assert rig.state() == "inactive"
    t1 = rig.now()
    for message in rig.samples_between(t1, t1 + 1.0):
        assert speed(message) < STILL_RAD_S and np.abs(positions(message) - HOME).max() < 1e-4


def test_configure_fails_naming_the_missing_camera(rig):
    rig.graph.wait_for_service("/camera_check/change_state", 60)
    assert not rig.transition("configure", node="/camera_check")
    assert rig.state("/camera_check") == "unconfigured"
    event, = rig.graph.collect(DiagnosticStatus, "/camera_check/events", qos=LATCHED,
                               predicate=lambda e: value(e, "event") == "transition_failed")
    assert event.message == "configure failed: no camera frames on /camera/image_raw for 2 s"


def test_activate_balances_and_deactivate_levels_the_plate(rig):
    rig.ensure_active()
    assert rig.controllers()["forward_position_controller"] == "active"
    rig.wait_until_moving()
    # once the first catch of the ball is over (the plate tilted, moving slowly)
    rig.graph.spin_until(lambda: speed(rig.latest[-1]) < 0.05 and np.abs(positions(rig.latest[-1]) - HOME).max() > 1e-3,
                         60, "the plate tilted and calm")
    t0 = rig.now()
    assert rig.transition("deactivate"), rig.manager.output()[-2000:]
    t1 = rig.now()
    assert rig.state() == "inactive"
    states = rig.controllers()
    assert states["forward_position_controller"] == states["scaled_joint_trajectory_controller"] == "inactive"
    # the balancing goes on until the switch to the levelling controller, tens of milliseconds
    # of simulated time after t0 (fewer on a slower machine): judge the path after that
    during = rig.samples_between(t0 + 0.25, t1)
    fastest = max(during, key=speed)
    timeline = " ".join(f"{stamp(m) - t0:.2f}:{speed(m):.2f}" for m in during[::25])
    assert speed(fastest) < 0.3 * 1.5, (f"the levelling was not smooth: {speed(fastest):.2f} rad/s at "
                                        f"{stamp(fastest) - t0:.2f} s of {t1 - t0:.2f} s (s:rad/s {timeline})")
    after = rig.samples_between(t1 + 0.2, t1 + 1.2)
    for message in after:
        assert np.abs(positions(message) - HOME).max() < 2e-3 and speed(message) < STILL_RAD_S


def _estop_holds(rig, t_call: float, until: float):
    late = rig.samples_between(t_call + 0.1, until)
    assert late, "no /joint_states after the stop"
    worst = max(late, key=speed)
    timeline = " ".join(f"{stamp(m) - t_call:.2f}:{speed(m):.1e}" for m in rig.samples_between(t_call, until)[::10])
    assert speed(worst) < STILL_RAD_S, (f"joint speed {speed(worst):.2e} rad/s at {stamp(worst) - t_call:.3f} s "
                                        f"after the call (s:rad/s {timeline})")


def test_the_emergency_stop_holds_the_arm_until_reset_and_reset_moves_nothing(rig):
    rig.ensure_active()
    rig.wait_until_moving()
    t_call, response = rig.trigger_at("/robot_manager/emergency_stop")
    assert response.success, response.message
    _estop_holds(rig, t_call, t_call + 2.0)
    rig.graph.spin_until(lambda: rig.latch and rig.latch[-1], 10, "the latch")
    event = rig.wait_for_event(lambda e: value(e, "event") == "emergency_stop", "the stop event")
    assert event.level == DiagnosticStatus.ERROR and value(event, "source") == "service"
    rig.graph.spin_until(lambda: rig.state() == "inactive", 30, "inactive after the stop")
    assert rig.controllers()["forward_position_controller"] == "inactive"
    assert not rig.transition("activate"), "activate must be refused while the stop is latched"
    refused = rig.launcher.run([executable("ros2py"), "lifecycle", "set", "/robot_manager", "activate",
                                "--spin-time", "30"], timeout=180)
    assert refused.returncode == 1 and refused.stdout.startswith("Transitioning failed: ") and \
        "the emergency stop is latched" in refused.stdout, refused.stdout   # the reason the node logged
    held = positions(rig.states[-1])
    response = rig.trigger("/robot_manager/reset_emergency_stop")
    assert response.success, response.message
    rig.graph.spin_until(lambda: not rig.latch[-1], 10, "the latch cleared")
    t_reset = rig.now()
    for message in rig.samples_between(t_reset, t_reset + 1.0):
        assert speed(message) < STILL_RAD_S and np.abs(positions(message) - held).max() < 1e-4
    assert rig.state() == "inactive"


def test_ros2py_lifecycle_drives_it_by_hand_and_survives_a_late_answer(rig):
    assert not (rig.latch and rig.latch[-1])

    def ros2py(*args):
        result = rig.launcher.run([executable("ros2py"), "lifecycle", *args, "--spin-time", "30"], timeout=180)
        return result.returncode, result.stdout

    assert ros2py("get", "/robot_manager") == (0, "inactive [2]\n")
    code, out = ros2py("list", "/robot_manager")
    assert code == 0 and "- activate [3]\n\tStart: inactive\n\tGoal: activating\n" in out, out
    code, out = ros2py("set", "/robot_manager", "fly")
    assert code == 1 and out.startswith("Unknown transition requested, available ones are:\n- cleanup [2]"), out
    assert ros2py("set", "/robot_manager", "activate") == (0, "Transitioning successful\n")
    # an answer later than --timeout (deactivate levels the plate for at least a second): get_state
    # says whether the transition went through
    code, out = ros2py("set", "/robot_manager", "deactivate", "--timeout", "0.5")
    assert (code, out.splitlines()[-1]) == (0, "Transitioning successful"), out
    assert rig.state() == "inactive"


def test_a_balancing_controller_switched_off_by_someone_else_ends_in_the_safe_state(rig):
    rig.ensure_active()
    rig.events.clear()
    result = rig.launcher.run([executable("ros2py"), "control", "switch_controllers", "--deactivate",
                               "forward_position_controller"], timeout=180)
    assert result.returncode == 0, result.stdout + result.stderr
    event = rig.wait_for_event(lambda e: value(e, "event") == "emergency_stop", "the stop event")
    assert value(event, "source") == "controller_stopped", event.message
    assert "'forward_position_controller' is inactive" in event.message
    rig.graph.spin_until(lambda: rig.state() == "inactive", 60, "inactive after the stop")
    assert rig.latch[-1]
    t0 = rig.now()
    _estop_holds(rig, t0 - 0.1, t0 + 1.0)


def _manager_pid(rig) -> int:
    match = re.search(r"ros2_control_node (\d+)", rig.sim.output())
    assert match, rig.sim.output()
    return int(match.group(1))


def test_a_stalled_manager_ends_in_the_safe_state(rig):
    rig.ensure_active()
    rig.events.clear()
    pid = _manager_pid(rig)
    os.kill(pid, signal.SIGSTOP)
    try:
        event = rig.wait_for_event(lambda e: value(e, "event") == "emergency_stop", "the stall's stop event", 60)
    finally:
        os.kill(pid, signal.SIGCONT)
    assert value(event, "source") == "manager_stalled" and "stopped updating" in event.message
    rig.graph.spin_until(lambda: rig.state() == "inactive", 90, "inactive after the stall")
    assert rig.controllers()["forward_position_controller"] == "inactive"
    assert rig.latch[-1]
    t0 = rig.now()
    _estop_holds(rig, t0 - 0.1, t0 + 1.0)


def test_a_hardware_error_ends_in_the_safe_state(rig):
    rig.ensure_active()
    rig.events.clear()
    assert rig.trigger("/sim/inject_hardware_error").success
    event = rig.wait_for_event(lambda e: value(e, "event") == "emergency_stop", "the hardware error's stop event")
    assert value(event, "source") == "hardware_error" and "ur5e_ball_balance" in event.message
    rig.graph.spin_until(lambda: rig.state() == "inactive", 60, "inactive after the hardware error")
    assert rig.latch[-1]
    assert rig.controllers()["forward_position_controller"] == "inactive"
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline:
        rig.graph.spin_for(0.2)
    assert "Traceback" not in rig.manager.output()
