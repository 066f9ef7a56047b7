"""Camera-to-command latency budget of the live simulated graph, stage by stage.

Starts the graph as scripts/sim_balance.sh does, on a private ROS domain with the project's
DDS settings and configuration files (config/sim.yaml, sim_manager.yaml, ball_tracker.yaml,
pid.yaml or mpc.yaml; --sim-param, --manager-param, --tracker-param and --controller-param
override single values): ros2_control_node hosting MujocoSystem (camera at --rate Hz,
--width x --height, latency_trace on), ball_tracker and the PID (or MPC) balance controller,
all on simulated time; optionally --busy N processes that each keep a core busy. After --warmup-s (homing,
engaging) it follows every camera frame for --seconds through:

  render            frame captured (sim loop) -> rendered (camera thread)      /sim/latency_trace
  image publish     rendered -> image written to DDS (its camera_info follows)  source timestamps
  image transport   DDS write -> DDS receipt in the tracker                     tracker ~/statistics
  decode            receipt -> callback -> numpy array (a view of the sample)   tracker ~/statistics
  track             markers, homography, ball, Kalman                            tracker ~/statistics
  state publish     /plate_pose + /ball_state                                   tracker ~/statistics
  controller        /ball_state written -> joint command written: state transport, the
                    controller's wake-up and compute                            source timestamps
  command -> hw     joint command written -> the manager's next cycle reads it -> written to
                    the hardware (MujocoSystem.write sets a new joint target)   /sim/latency_trace

The stages add up to the whole chain, camera capture -> joint command written to the
hardware; each is printed as median and p95 (ms). Then the live monitor's camera-to-command
(ball_balance/benchmark/wall_latency.py: the frame's stamp mapped to the wall clock through
/clock, -> the first /plate_cmd written after its /ball_state), beside "capture -> command
written" measured here from the latency trace: the two should agree within a few ms.
Times are wall-clock DDS source/receipt timestamps of each message (one host, one clock),
matched by the frame's stamp; a controller command is matched to the first one written after the frame's /ball_state.
For reference (not part of the sum), the two DDS hops inside "controller" and
"command -> hw", measured to this process: a stand-in for the hops to the controller and
to the manager, which do not report their receipt times.

usage: python benchmarks/latency_budget_bench.py [--rate 60] [--width 640 --height 480]
           [--seconds 20] [--warmup-s 8] [--busy 1] [--controller pid] [--camera-thread]
           [--sim-param NAME=VALUE ...] [--manager-param NAME:=VALUE ...] [--tracker-param NAME:=VALUE ...]
           [--controller-param NAME:=VALUE ...]
"""
from __future__ import annotations

import argparse
import bisect
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))
from harness import DomainLease, Graph, executable, ros_env, stop_groups  # noqa: E402

STAGES = ("render", "image publish", "image transport", "decode", "track", "state publish", "controller",
          "command -> hw")
REFERENCE = ("(state transport, to this process)", "(command transport, to this process)")
BUSY = "while True:\n    pass\n"
CONTROLLER_EXECUTABLES = {"pid": "ball_balance_controller", "mpc": "ball_balance_mpc"}
COMMAND_CONTROLLERS = {"pid": "forward_position_controller", "mpc": "scaled_joint_trajectory_controller"}


def start_graph(args, env, workdir: Path) -> list:
    from ball_balance import robot

    urdf = workdir / "sim.urdf"
    params = {"sim_config": str(ROOT / "config" / "sim.yaml"),   # as scripts/sim_balance.sh; these win
              "camera_rate_hz": args.rate, "camera_width": args.width, "camera_height": args.height,
              "latency_trace": True, "robot_description_file": str(urdf),
              "camera_process": not args.camera_thread}
    for param in args.sim_param:
        name, _, value = param.partition("=")
        params[name] = value
    urdf.write_text(robot.robot_description("mujoco", params))
    config = ROOT / "config"
    # PID: forward position commands; MPC: single-point trajectories (as scripts/sim_balance.sh)
    active, inactive = COMMAND_CONTROLLERS[args.controller], COMMAND_CONTROLLERS["mpc" if args.controller == "pid"
                                                                                  else "pid"]
    commands = [
        [executable("ros2_control_node"), "--ros-args", "--params-file", str(config / "ur_controllers.yaml"),
         "--params-file", str(config / "sim_manager.yaml"),  # scheduling as scripts/sim_arm.sh
         "-p", f"robot_description_file:={urdf}",
         "-p", f"activate_controllers:=[joint_state_broadcaster, {active}]",
         "-p", f"inactive_controllers:=[{inactive}]", *overrides(args.manager_param)],
        [executable("ball_tracker"), "--ros-args", "--params-file", str(config / "ball_tracker.yaml"),
         "-p", "use_sim_time:=true", *overrides(args.tracker_param)],
        [executable(CONTROLLER_EXECUTABLES[args.controller]), "--ros-args", "--params-file",
         str(config / f"{args.controller}.yaml"), "-p", "use_sim_time:=true", *overrides(args.controller_param)],
    ]
    commands += [[sys.executable, "-c", BUSY]] * args.busy
    logs = [open(workdir / f"process{i}.log", "wb") for i in range(len(commands))]
    return [subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
            for cmd, log in zip(commands, logs)]


def cpu_seconds(pid: int) -> float:
    """CPU time (user + system, all threads) of a process and its children still running, s."""
    tick = os.sysconf("SC_CLK_TCK")
    total = 0.0
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        total += (int(fields[11]) + int(fields[12])) / tick
        for task in Path(f"/proc/{pid}/task").iterdir():
            for child in (task / "children").read_text().split():
                total += cpu_seconds(int(child))
    except (FileNotFoundError, ProcessLookupError, IndexError):
        pass
    return total


def process_cpu(pid: int) -> float:
    """CPU time of one process alone (all threads), s."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except FileNotFoundError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def overrides(params) -> list:
    """["name:=value", ...] -> ["-p", "name:=value", ...]"""
    return [arg for param in params for arg in ("-p", param)]


class Recorder:
    """Every message's wall-clock source (write) and receipt times, keyed by frame stamp."""

    def __init__(self, node, controller: str):
        from ball_tracker_msgs.msg import BallState
        from geometry_msgs.msg import Vector3Stamped
        from pal_statistics_msgs.msg import Statistics
        from rclpy.qos import QoSProfile, qos_profile_sensor_data
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import CameraInfo
        from std_msgs.msg import Float64MultiArray, Header
        from trajectory_msgs.msg import JointTrajectory

        from ball_balance.benchmark.wall_latency import CameraToCommand

        self.recording = False
        self.commands_seen = 0                # before recording too: the graph is up
        self.trace = defaultdict(dict)        # event -> frame stamp (ns) -> wall ns
        self.hardware_writes = []             # wall ns of each new joint target
        self.image_written = {}               # stamp -> wall ns (its camera_info, written right after)
        self.state = {}                       # stamp -> (written wall ns, received wall ns)
        self.commands = []                    # (written wall ns, received wall ns), in order
        self.tracker = {}                     # stamp -> {stage: ms}
        self.clock = []                       # (wall s, sim s) of each /clock while recording
        self.monitor = CameraToCommand()      # the live monitor's camera-to-command, same samples
        node.create_subscription(Header, "/sim/latency_trace", self.on_trace, QoSProfile(depth=100))
        node.create_subscription(CameraInfo, "/camera/camera_info", self.on_camera_info, qos_profile_sensor_data)
        node.create_subscription(BallState, "/ball_state", self.on_state, qos_profile_sensor_data)
        if controller == "pid":
            node.create_subscription(Float64MultiArray, "/forward_position_controller/commands", self.on_command, 10)
        else:
            node.create_subscription(JointTrajectory, "/scaled_joint_trajectory_controller/joint_trajectory",
                                     self.on_command, 10)
        node.create_subscription(Statistics, "/ball_tracker/statistics/full", self.on_statistics, 100)
        node.create_subscription(Clock, "/clock", self.on_clock, QoSProfile(depth=1))
        node.create_subscription(Vector3Stamped, "/plate_cmd", self.on_plate_cmd, 10)

    @staticmethod
    def stamp_ns(stamp) -> int:
        return stamp.sec * 1_000_000_000 + stamp.nanosec

    def on_trace(self, msg, info):
        if not self.recording:
            return
        if msg.frame_id == "command":
            self.hardware_writes.append(info["source_timestamp"])
        else:
            self.trace[msg.frame_id][self.stamp_ns(msg.stamp)] = info["source_timestamp"]

    def on_camera_info(self, msg, info):
        if self.recording:
            self.image_written[self.stamp_ns(msg.header.stamp)] = info["source_timestamp"]

    def on_state(self, msg, info):
        if self.recording:
            self.state[self.stamp_ns(msg.header.stamp)] = (info["source_timestamp"], info["received_timestamp"])
            self.monitor.add_state(self.stamp_ns(msg.header.stamp) * 1e-9, info["source_timestamp"] * 1e-9)

    def on_plate_cmd(self, msg, info):
        if self.recording:
            self.monitor.add_command(info["source_timestamp"] * 1e-9)

    def on_command(self, msg, info):
        self.commands_seen += 1
        if self.recording:
            self.commands.append((info["source_timestamp"], info["received_timestamp"]))

    def on_clock(self, msg, info):
        if self.recording:
            self.clock.append((time.monotonic(), msg.clock.sec + msg.clock.nanosec * 1e-9))
        self.monitor.add_clock(msg.clock.sec + msg.clock.nanosec * 1e-9, info["source_timestamp"] * 1e-9)

    def sim_seconds(self) -> tuple[float, float]:
        """(simulated s, wall s) between the first and the last /clock received while recording."""
        if len(self.clock) < 2:
            return 0.0, 0.0
        return self.clock[-1][1] - self.clock[0][1], self.clock[-1][0] - self.clock[0][0]

    def on_statistics(self, msg):
        if not self.recording:
            return
        values = {s.name: s.value for s in msg.statistics}
        if "stamp_s" in values:
            self.tracker[int(round(values["stamp_s"] * 1e9))] = values

    def chains(self):
        """Per frame: {stage: ms} and the whole chain, for frames followed end to end."""
        command_writes = [c[0] for c in self.commands]
        hardware = sorted(self.hardware_writes)
        rows = []
        for stamp, captured in self.trace["capture"].items():
            rendered = self.trace["rendered"].get(stamp)
            image = self.image_written.get(stamp)
            stats = self.tracker.get(stamp)
            state = self.state.get(stamp)
            if None in (rendered, image, stats, state):
                continue
            i = bisect.bisect_right(command_writes, state[0])
            if i == len(command_writes):
                continue
            command_written, command_received = self.commands[i]
            j = bisect.bisect_right(hardware, command_written)
            if j == len(hardware):
                continue
            ms = 1e-6
            row = {"render": (rendered - captured) * ms, "image publish": (image - rendered) * ms,
                   "image transport": stats["transport_ms"],
                   "decode": stats["take_ms"] + stats["decode_ms"],
                   "track": stats["total_ms"], "state publish": stats["publish_ms"],
                   "controller": (command_written - state[0]) * ms,
                   "command -> hw": (hardware[j] - command_written) * ms,
                   REFERENCE[0]: (state[1] - state[0]) * ms,
                   REFERENCE[1]: (command_received - command_written) * ms,
                   "capture -> hardware write": (hardware[j] - captured) * ms,
                   "capture -> command written": (command_written - captured) * ms,
                   "capture -> /ball_state written": (state[0] - captured) * ms}
            rows.append(row)
        return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=60.0, help="camera rate (Hz)")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--warmup-s", type=float, default=8.0,
                        help="after the first joint command: homing and engaging before recording")
    parser.add_argument("--busy", type=int, default=1, help="extra processes each keeping a core busy")
    parser.add_argument("--controller", default="pid", choices=("pid", "mpc"))
    parser.add_argument("--camera-thread", action="store_true",
                        help="render in a thread of the manager (camera_process:=false) instead of a child process")
    parser.add_argument("--sim-param", action="append", default=[], metavar="NAME=VALUE",
                        help="a MujocoSystem hardware parameter (repeatable), e.g. camera_priority=30")
    parser.add_argument("--manager-param", action="append", default=[], metavar="NAME:=VALUE",
                        help="override a config/sim_manager.yaml value (repeatable), e.g. thread_priority:=50")
    parser.add_argument("--tracker-param", action="append", default=[], metavar="NAME:=VALUE",
                        help="override a config/ball_tracker.yaml value (repeatable)")
    parser.add_argument("--controller-param", action="append", default=[], metavar="NAME:=VALUE",
                        help="override a config/<controller>.yaml value (repeatable), e.g. control_trigger:=ball_state")
    args = parser.parse_args()

    lease = DomainLease()
    env = ros_env(lease.domain_id)
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as workdir:
        processes = start_graph(args, env, Path(workdir))
        graph = Graph(lease.domain_id, "latency_budget_bench")
        recorder = Recorder(graph.node, args.controller)
        try:
            graph.wait_until(lambda: recorder.commands_seen > 0, 120.0)  # start-up on a busy machine
            graph.spin_for(args.warmup_s)
            names = ("manager", "tracker", "controller")
            cpu0 = {name: process_cpu(p.pid) for name, p in zip(names, processes, strict=False)}
            cpu0["camera"] = cpu_seconds(processes[0].pid) - cpu0["manager"]
            recorder.recording = True
            graph.spin_for(args.seconds)
            cpu = {name: process_cpu(p.pid) - cpu0[name] for name, p in zip(names, processes, strict=False)}
            cpu["camera"] = cpu_seconds(processes[0].pid) - cpu["manager"] - cpu0["manager"] - cpu0["camera"]
            load = os.getloadavg()[0]
        finally:
            graph.close()
            stop_groups(processes, grace_s=10.0)
            lease.release()
        rows = recorder.chains()
    frames = len(recorder.trace["capture"])
    where = "a thread of the manager" if args.camera_thread else "a child process"
    print(f"camera {args.rate:.0f} Hz {args.width}x{args.height} rendered in {where}, {args.controller}, "
          f"{args.seconds:.0f} s, "
          f"{args.busy} busy process(es); load average {load_before:.1f} before, {load:.1f} at the end")
    if args.sim_param or args.manager_param or args.tracker_param or args.controller_param:
        print(f"overrides: sim {args.sim_param or '-'}, manager {args.manager_param or '-'}, "
              f"tracker {args.tracker_param or '-'}, controller {args.controller_param or '-'}")
    print(f"frames captured {frames}, rendered {len(recorder.trace['rendered'])}, tracked "
          f"{len(recorder.tracker)}, /ball_state {len(recorder.state)}, followed to the hardware {len(rows)}")
    sim_s, wall_s = recorder.sim_seconds()
    if sim_s > 0:
        rendered = len(recorder.trace["rendered"])
        print(f"real-time factor {sim_s / wall_s:.2f} (/clock: {sim_s:.1f} simulated s in {wall_s:.1f} s); per "
              f"simulated s: frames captured {frames / sim_s:.1f}, rendered {rendered / sim_s:.1f}, "
              f"/ball_state {len(recorder.state) / sim_s:.1f}")
        print("CPU s per simulated s: " + ", ".join(f"{name} {value / sim_s:.2f}" for name, value in cpu.items()))
    if not rows:
        print("no frame followed end to end (is the controller engaged? see the process logs)")
        return 1
    print(f"\n{'stage':<38}{'median ms':>10}{'p95 ms':>9}")
    for stage in (*STAGES, "capture -> /ball_state written", "capture -> command written", "capture -> hardware write",
                  *REFERENCE):
        values = np.array([r[stage] for r in rows])
        if stage in ("capture -> /ball_state written", REFERENCE[0]):
            print("-" * 57)
        print(f"{stage:<38}{np.median(values):>10.2f}{np.percentile(values, 95):>9.2f}")
    monitor_ms = 1e3 * recorder.monitor.latencies_s()
    command_ms = np.array([r["capture -> command written"] for r in rows])
    if monitor_ms.size:
        print(f"\nlive monitor's camera-to-command (stamp via /clock -> /plate_cmd written), {monitor_ms.size} states: "
              f"mean {np.mean(monitor_ms):.2f}, median {np.median(monitor_ms):.2f}, p95 "
              f"{np.percentile(monitor_ms, 95):.2f} ms; here capture -> command written: mean "
              f"{np.mean(command_ms):.2f}, median {np.median(command_ms):.2f}, "
              f"p95 {np.percentile(command_ms, 95):.2f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
