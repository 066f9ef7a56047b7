"""`ball_balance_policy`: the learned balancing policy as a node (same topics as the PID node).

/ball_state -> 6 joint positions on /forward_position_controller/commands
(std_msgs/Float64MultiArray, JOINT_NAMES order), plus /plate_cmd and /ball_reference (see
balance_node_base), so it runs unchanged against the simulated arm or the UR driver. The tilt
is the PID's plus the ONNX policy's bounded correction (ball_balance/policy/tilt_law.py),
through the same safety supervisor, latency prediction, IK and shaping as the PID and MPC.

The model is checked at start-up: a file whose metadata does not fit (observation layout,
action, rate, the PID it was trained on) stops the node with one line. The policy keeps a
history of ticks, so the node steps on its own timer at the model's rate (control_trigger
'timer' in config/policy.yaml). The PID gains are read-only here (the correction was
learned for them); the reference_* parameters can be changed at run time. Inference time,
corrections and held ticks are logged every 10 s. config/policy.yaml holds what we run.
"""
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from std_msgs.msg import Float64MultiArray

from ball_balance.control.config import PID_GAINS_SCHEMA
from ball_balance.control.pipeline import ControlPipeline
from ball_balance.nodes.balance_node_base import BalanceControllerNode
from ball_balance.policy.params import POLICY_SCHEMA
from controller_manager_py.controllers.policy_model import PolicyModelError
from controller_manager_py.ros.node_main import StartupError, main_for

PID_GAINS = {p.name for p in PID_GAINS_SCHEMA}


class PolicyControllerNode(BalanceControllerNode):
    SCHEMA = POLICY_SCHEMA
    CONTROLLER = "policy"

    def __init__(self):
        super().__init__("ball_balance_policy")
        self.command_pub = self.create_publisher(Float64MultiArray, "/forward_position_controller/commands", 10)
        self._inference_us = []
        self.create_timer(10.0, self.log_policy)

    def announce(self) -> None:
        super().announce()
        law = self.pipeline.law
        training = law.runner.metadata.training
        self.get_logger().info(f"policy {law.runner.where} (seed {training.get('seed')}, commit "
                               f"{str(training.get('commit'))[:12]}, {training.get('method', '')})")

    def make_pipeline(self) -> ControlPipeline:
        try:
            return super().make_pipeline()
        except PolicyModelError as error:
            raise StartupError(str(error)) from None

    def on_set_parameters(self, params) -> SetParametersResult:
        for p in params:
            if p.name in PID_GAINS:
                return SetParametersResult(successful=False, reason=f"'{p.name}' is read-only here: the policy's "
                                                                    "correction was trained for the configured PID")
        return super().on_set_parameters(params)

    def control_step(self, steady: float) -> None:
        law = self.pipeline.law
        before = law.inferences
        super().control_step(steady)
        if law.inferences != before:
            self._inference_us.append(law.last_inference_s * 1e6)

    def publish_joints(self, q_cmd, stamp) -> None:
        self.command_pub.publish(Float64MultiArray(data=[float(v) for v in q_cmd]))

    def log_policy(self) -> None:
        law = self.pipeline.law
        if self._inference_us:
            us = np.array(self._inference_us)
            self.get_logger().info(f"policy inference p50 {np.percentile(us, 50):.0f} us, p99 "
                                   f"{np.percentile(us, 99):.0f} us over {len(us)} ticks; correction now "
                                   f"({law.last_correction[0]:+.4f}, {law.last_correction[1]:+.4f}) rad; "
                                   f"held ticks (non-finite) {law.held_count}")
            self._inference_us.clear()


main = main_for(PolicyControllerNode)
