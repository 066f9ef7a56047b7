"""`ball_balance_controller`: PID balance controller (docs/design.md section 4).

/ball_state -> 6 joint positions on /forward_position_controller/commands
(std_msgs/Float64MultiArray, JOINT_NAMES order), plus /plate_cmd and /ball_reference (see
balance_node_base). Gains kp, ki, kd, i_limit_rad,
antiwindup_time_s and the reference_* parameters can be changed at run time
(`ros2 param set /ball_balance_controller kp 2.0`); config/pid.yaml holds the defaults we run.
"""
from std_msgs.msg import Float64MultiArray

from ball_balance.control.config import PID_SCHEMA
from ball_balance.nodes.balance_node_base import BalanceControllerNode
from controller_manager_py.ros.node_main import main_for


class PidControllerNode(BalanceControllerNode):
    SCHEMA = PID_SCHEMA
    CONTROLLER = "pid"

    def __init__(self):
        super().__init__("ball_balance_controller")
        self.command_pub = self.create_publisher(Float64MultiArray, "/forward_position_controller/commands", 10)

    def publish_joints(self, q_cmd, stamp) -> None:
        self.command_pub.publish(Float64MultiArray(data=[float(v) for v in q_cmd]))


main = main_for(PidControllerNode)
