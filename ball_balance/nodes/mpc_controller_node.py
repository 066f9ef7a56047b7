"""`ball_balance_mpc`: MPC balance controller (docs/design.md section 4).

/ball_state -> a single-point trajectory_msgs/JointTrajectory on
/scaled_joint_trajectory_controller/joint_trajectory (JOINT_NAMES, positions, reached
`trajectory_point_time_s` after receipt: by default one control period, so the trajectory
controller ramps each target in by the time the next comes), plus /plate_cmd and /ball_reference (see
balance_node_base). The QP (OSQP, see ball_balance/control/mpc.py) is solved every control
step; step-time statistics are logged every 10 s. config/mpc.yaml holds the defaults we run.
"""
import time

import numpy as np
from builtin_interfaces.msg import Duration
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ball_balance.control.config import MPC_NODE_SCHEMA
from ball_balance.nodes.balance_node_base import BalanceControllerNode
from ball_balance.robot import JOINT_NAMES
from controller_manager_py.parameters import Param
from controller_manager_py.ros.node_main import main_for

SCHEMA = MPC_NODE_SCHEMA + [
    Param("trajectory_point_time_s", 0.0, "time_from_start of the single trajectory point; 0: one control "
          "period (1 / control_rate_hz)", "s", 0.0, 1.0, read_only=True),
]


class MpcControllerNode(BalanceControllerNode):
    SCHEMA = SCHEMA
    CONTROLLER = "mpc"

    def __init__(self):
        super().__init__("ball_balance_mpc")
        self.command_pub = self.create_publisher(
            JointTrajectory, "/scaled_joint_trajectory_controller/joint_trajectory", 10)
        # a point further out than the next step is never reached: each new one replaces it,
        # and the plate lags the command
        t = self.params["trajectory_point_time_s"] or 1.0 / self.params["control_rate_hz"]
        self._time_from_start = Duration(sec=int(t), nanosec=int(round((t % 1.0) * 1e9)))
        self._tick_times_s = []
        self.create_timer(10.0, self.log_timing)

    def control_step(self, steady: float) -> None:
        t0 = time.perf_counter()
        super().control_step(steady)
        if self.pipeline.safety.mode.value == "engaged":
            self._tick_times_s.append(time.perf_counter() - t0)

    def publish_joints(self, q_cmd, stamp) -> None:
        msg = JointTrajectory(joint_names=list(JOINT_NAMES))
        msg.points = [JointTrajectoryPoint(positions=[float(v) for v in q_cmd],
                                           time_from_start=self._time_from_start)]
        self.command_pub.publish(msg)

    def log_timing(self) -> None:
        if self._tick_times_s:
            ms = np.array(self._tick_times_s) * 1e3
            self.get_logger().info(f"engaged tick time p50 {np.percentile(ms, 50):.2f} ms, p99 "
                                   f"{np.percentile(ms, 99):.2f} ms over {len(ms)} ticks; QP fallbacks "
                                   f"{self.pipeline.mpc.failures}")
            self._tick_times_s.clear()


main = main_for(MpcControllerNode)
