"""Faults injected into the live simulated graph, and what they did.

A case runs against the whole graph (MuJoCo arm in ros2_control_node, robot_state_publisher,
ball_tracker on the rendered camera, one balance controller), composed by `graph_commands`
and started by the caller (the benchmark's or the test's process launcher):

  none              nothing injected (the baseline)
  rogue_far         a second /ball_state publisher, 30 Hz for 2 s: x = 5 m, fresh stamps
  rogue_old         ... its stamps 10 s old
  rogue_ahead       ... its stamps 10 s in the future
  rogue_elsewhere   ... a plausible ball at (-0.1, 0.1) m, fresh stamps
  kill_manager      ros2_control_node killed (SIGKILL): /joint_states and /clock stop
  hand_two_markers  a hand over markers 0 and 1 for 1 s, twice (a relay paints it on the
                    camera images the tracker sees)

`run_case` waits for the controller to engage, lets the ball settle on the reference, injects
the fault and watches (simulated time from /sim/ball_truth): whether the ball stayed on the
plate, how often the controller changed mode, the largest commanded tilt, and what the
controller logged. Needs rclpy (runs in a process with the graph's ROS_DOMAIN_ID).
"""
from __future__ import annotations

import math
import os
import re
import signal
import time
from pathlib import Path
from typing import Callable, List, Optional, Tuple

CASES = ("none", "rogue_far", "rogue_old", "rogue_ahead", "rogue_elsewhere", "kill_manager", "hand_two_markers")
ROGUES = {"rogue_far": dict(x=5.0), "rogue_old": dict(stamp_offset_s=-10.0),
          "rogue_ahead": dict(stamp_offset_s=10.0), "rogue_elsewhere": dict(x=-0.1, y=0.1)}
ROGUE_NODE = "fault_rogue_ball_state"
ROGUE_NAME_WAIT_S = 30.0   # wall seconds a rogue may keep publishing after its window until it is named
RELAY_TOPIC = "/fault_injection/image_raw"
HIDDEN_MARKERS = (0, 1)


def graph_commands(root: Path, controller: str, case: str,
                   reference: Tuple[str, float, float] = ("circle", 0.08, 10.0),
                   ball_xy: Tuple[float, float] = (0.05, -0.03),
                   truth_fed: bool = False) -> List[Tuple[str, List[str]]]:
    """(name, argv) of each process of the graph for `case` (the tracker reads the relay for
    the hand case); start "sim" first. `truth_fed`: no camera and tracker, the simulation
    publishes /ball_state from the true ball plus noise (far less CPU; not for the hand case)."""
    if truth_fed and case == "hand_two_markers":
        raise ValueError("the hand case needs the camera and the tracker (truth_fed=False)")
    exe, yaml = {"pid": ("ball_balance_controller", "pid.yaml"), "mpc": ("ball_balance_mpc", "mpc.yaml")}[controller]
    kind, radius, period = reference
    sim_config = "sim_truth_fed.yaml" if truth_fed else "sim.yaml"
    sim = [str(root / "scripts" / "sim_arm.sh"), "--sim-config", str(root / "config" / sim_config),
           "--param", f"ball_x={ball_xy[0]}", "--param", f"ball_y={ball_xy[1]}"]
    if controller == "mpc":
        sim.append("--trajectory")
    tracker = ["ball_tracker", "--ros-args", "--params-file", str(root / "config" / "ball_tracker.yaml"),
               "-p", "use_sim_time:=true"]
    if case == "hand_two_markers":
        tracker += ["-p", f"image_topic:={RELAY_TOPIC}"]
    ctrl = [exe, "--ros-args", "--params-file", str(root / "config" / yaml), "-p", "use_sim_time:=true",
            "-p", f"reference_kind:={kind}", "-p", f"reference_radius_m:={float(radius)}",
            "-p", f"reference_period_s:={float(period)}"]
    if truth_fed:
        return [("sim", sim), ("controller", ctrl)]
    return [("sim", sim), ("tracker", tracker), ("controller", ctrl)]


def manager_pid(sim_output: str) -> Optional[int]:
    """ros2_control_node's pid, from the line sim_arm.sh prints when it starts."""
    match = re.search(r"ros2_control_node (\d+)", sim_output)
    return int(match.group(1)) if match else None


class _Rogue:
    """A second /ball_state publisher (its own node), stamped on the graph's simulated clock."""

    def __init__(self, context, executor, clock_s: Callable[[], float], x=0.0, y=0.0, stamp_offset_s=0.0):
        import rclpy
        from ball_tracker_msgs.msg import BallState
        from rclpy.qos import qos_profile_sensor_data

        self.node = rclpy.create_node(ROGUE_NODE, context=context)
        self.executor = executor
        executor.add_node(self.node)
        pub = self.node.create_publisher(BallState, "/ball_state", qos_profile_sensor_data)

        def publish():
            msg = BallState(x=float(x), y=float(y), tracking_valid=True, ball_found=True, markers_found=4)
            msg.header.frame_id = "plate_center"
            stamp_ns = int((clock_s() + stamp_offset_s) * 1e9)
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
            pub.publish(msg)

        self.node.create_timer(1 / 30, publish)

    def close(self) -> None:
        self.executor.remove_node(self.node)
        self.node.destroy_node()


class _HandRelay:
    """Passes /camera/image_raw on to RELAY_TOPIC, painting a hand over HIDDEN_MARKERS while
    `hidden()` is true. Marker centres are projected with the camera_info intrinsics for the
    overhead camera `camera_height_m` above the level plate (camera x = plate x, y = -plate y)."""

    def __init__(self, node, hidden: Callable[[], bool], camera_height_m: float = 0.65, scale: float = 2.2):
        from rclpy.qos import qos_profile_sensor_data
        from sensor_msgs.msg import CameraInfo, Image

        self.hidden, self.h, self.scale = hidden, camera_height_m, scale
        self.k = None
        self.pub = node.create_publisher(Image, RELAY_TOPIC, qos_profile_sensor_data)
        node.create_subscription(CameraInfo, "/camera/camera_info", self.on_info, qos_profile_sensor_data)
        node.create_subscription(Image, "/camera/image_raw", self.on_image, qos_profile_sensor_data)

    def on_info(self, msg) -> None:
        self.k = msg.k

    def on_image(self, msg) -> None:
        if self.k is not None and self.hidden():
            import cv2
            import numpy as np

            from ball_balance.plate_geometry import MARKER_CENTRES_M, MARKER_SIDE_M
            from ball_balance.ros.images import decode_image, encode_image
            from ball_balance.sim.camera import GLOVE_BGR

            image, _ = decode_image(msg)
            if image is None:
                return
            image = image.copy()
            fx, cx, fy, cy = self.k[0], self.k[2], self.k[4], self.k[5]
            half = self.scale * MARKER_SIDE_M / 2.0
            for marker_id in HIDDEN_MARKERS:
                mx, my = MARKER_CENTRES_M[marker_id]
                corners = [(cx + fx * (mx + dx) / self.h, cy - fy * (my + dy) / self.h)
                           for dx, dy in ((-half, -half), (half, -half), (half, half), (-half, half))]
                cv2.fillConvexPoly(image, np.round(np.array(corners)).astype(np.int32), GLOVE_BGR)
            msg = encode_image(image, msg.header.stamp, msg.header.frame_id)
        self.pub.publish(msg)


def _stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


LOG_PATTERNS = ("second publisher", "refused", "no /joint_states", "no /clock", "commands stopped", "resuming",
                "mode returning", "mode holding")


def summarize_log(lines: List[str], limit: int = 2) -> str:
    """The controller's fault-relevant log lines, shortened: the first of each kind."""
    picked = {}
    for line in lines:
        text = re.sub(r" \(refused so far:.*\)$", "", line.split("]: ", 1)[-1].strip())
        for pattern in LOG_PATTERNS:
            # the first line of each kind; a second publisher's: the first that names it
            if pattern in text and (pattern not in picked or "unlisted" in picked[pattern]):
                picked[pattern] = text[:110]
                break
    return " | ".join(list(picked.values())[:limit]) if picked else "-"


FAULT_TAIL_S = 0.5  # simulated time after a fault during which commands still count as its effect


def _max_tilt(cmds) -> float:
    return max((max(abs(c.vector.x), abs(c.vector.y)) for c in cmds), default=0.0)


def run_case(graph, case: str, controller_output: Callable[[], str], sim_output: Callable[[], str],
             settle_s: float = 6.0, fault_s: float = 2.0, after_s: float = 5.0,
             engage_timeout_s: float = 180.0) -> dict:
    """Inject `case` into the running graph and watch it; `graph` has .node, .executor, .context,
    .spin_until, .wait_until (test/harness.py's Graph). Returns the row of the table."""
    from ball_tracker_msgs.msg import BallState
    from geometry_msgs.msg import PointStamped, Vector3Stamped
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from std_msgs.msg import Bool

    from ball_balance.plate_geometry import PLATE_SIDE_M

    node = graph.node
    truth, cmds, states, refs, dropped = [], [], [], [], []
    node.create_subscription(BallState, "/sim/ball_truth", truth.append, qos_profile_sensor_data)
    node.create_subscription(BallState, "/ball_state", states.append, qos_profile_sensor_data)
    node.create_subscription(Vector3Stamped, "/plate_cmd", cmds.append, 10)
    node.create_subscription(PointStamped, "/ball_reference", refs.append, 10)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    node.create_subscription(Bool, "/sim/ball_dropped", lambda m: dropped.append(bool(m.data)), latched)

    def sim_now() -> float:
        return _stamp(truth[-1]) if truth else 0.0

    t_fault = [math.inf]

    def hidden() -> bool:   # 1 s hidden, 1 s visible, 1 s hidden
        dt = sim_now() - t_fault[0]
        return 0.0 <= dt < 1.0 or 2.0 <= dt < 3.0

    if case == "hand_two_markers":
        _HandRelay(node, hidden)
        fault_s = max(fault_s, 3.0)
    graph.spin_until(lambda: refs and truth, engage_timeout_s, f"the controller to engage ({case})")
    t_engaged = _stamp(refs[0])
    graph.spin_until(lambda: any(dropped) or sim_now() >= t_engaged + settle_s, 120, "the ball to settle")
    if any(dropped):   # nothing injected yet: the controller's own failure, not the fault's
        raise RuntimeError(f"the ball dropped before the fault ({case}) was injected")
    log_start = len(controller_output().splitlines())
    t_fault[0] = sim_now()
    row = dict(case=case, kept="yes", mode_flips=0, max_tilt_rad=0.0, min_markers="-", logged="-")
    rogue = None
    if case in ROGUES:
        rogue = _Rogue(graph.context, graph.executor, sim_now, **ROGUES[case])
    if case == "kill_manager":
        pid = manager_pid(sim_output())
        if pid is None:
            raise RuntimeError("ros2_control_node's pid not found in sim_arm.sh's output")
        os.kill(pid, signal.SIGKILL)
        n_before, t_kill = len(cmds), time.monotonic()
        graph.spin_until(lambda: "commands stopped" in controller_output() or time.monotonic() - t_kill > 8.0, 10)
        stopped_after = time.monotonic() - t_kill
        n_at_stop = len(cmds)
        deadline = time.monotonic() + 3.0
        graph.spin_until(lambda: time.monotonic() > deadline, 5)
        lines = controller_output().splitlines()[log_start:]
        row.update(kept="n/a (sim killed)", max_tilt_rad=float("nan"),
                   mode_flips=sum(1 for line in lines if "mode " in line),
                   logged=summarize_log(lines, 3) + f" [stop said after {stopped_after:.1f} s; commands in the "
                   f"3 s after: {len(cmds) - n_at_stop}, before it: {n_at_stop - n_before}]")
        return row
    try:
        graph.spin_until(lambda: any(dropped) or sim_now() >= t_fault[0] + fault_s, 120, "the fault window")
        if rogue is not None:
            # the controller names a second publisher once the ROS graph tells it the node's name,
            # which on a loaded machine can take longer than the fault window: the rogue keeps
            # publishing until it is named or ROGUE_NAME_WAIT_S more have passed
            graph.wait_until(lambda: any(dropped) or ROGUE_NODE in controller_output(), ROGUE_NAME_WAIT_S)
            fault_s = max(fault_s, sim_now() - t_fault[0])
    finally:
        if rogue is not None:
            rogue.close()
    graph.spin_until(lambda: any(dropped) or sim_now() >= t_fault[0] + fault_s + after_s, 120, "the watch window")
    half = PLATE_SIDE_M / 2.0
    off = any(max(abs(m.x), abs(m.y)) > half for m in truth if _stamp(m) >= t_fault[0])
    window = [c for c in cmds if _stamp(c) >= t_fault[0]]
    # while the fault lasts (and FAULT_TAIL_S after, for commands computed from it): its own
    # effect, apart from what a starved controller does later on a busy machine
    during = [c for c in window if _stamp(c) <= t_fault[0] + fault_s + FAULT_TAIL_S]
    lines = controller_output().splitlines()[log_start:]
    row.update(kept="no" if any(dropped) or off else "yes",
               mode_flips=sum(1 for line in lines if "mode " in line),
               max_tilt_rad=_max_tilt(window), max_tilt_during_fault_rad=_max_tilt(during),
               logged=summarize_log(lines))
    if case == "hand_two_markers":
        seen = [s.markers_found for s in states if t_fault[0] <= _stamp(s) <= t_fault[0] + fault_s]
        row["min_markers"] = str(min(seen)) if seen else "-"
    return row


def format_rows(rows: List[dict]) -> str:
    head = f"{'controller':10} {'case':17} {'ball kept':17} {'mode flips':>10} {'max tilt':>9} {'markers':>7}  logged"
    out = [head, "-" * len(head)]
    for r in rows:
        tilt = "n/a" if math.isnan(r["max_tilt_rad"]) else f"{r['max_tilt_rad']:.3f}"
        out.append(f"{r.get('controller', ''):10} {r['case']:17} {r['kept']:17} {r['mode_flips']:>10} {tilt:>9} "
                   f"{r['min_markers']:>7}  {r['logged']}")
    return "\n".join(out)
