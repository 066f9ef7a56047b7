"""The learned policy node over DDS: same topics as the PID node, commands toward the ball;
a model that does not fit stops it at start-up with one line."""
import math

import numpy as np
import pytest
from geometry_msgs.msg import Vector3Stamped
from std_msgs.msg import Float64MultiArray
from test_balance_controllers import FakeWorld, _kinematics

from ball_balance.policy.observation import flat_names
from harness import ROOT, executable

pytestmark = pytest.mark.integration
DATA = ROOT / "test" / "unit" / "policy" / "data"
WIDTH = len(flat_names())   # the ball controller's observation; wrong_width.onnx's graph takes two fewer


def _cmd(*params):
    cmd = [executable("ball_balance_policy"), "--ros-args", "--params-file", str(ROOT / "config" / "policy.yaml")]
    for p in params:
        cmd += ["-p", p]
    return cmd


def test_policy_node_tilts_toward_the_ball_with_finite_six_joint_commands(launcher, graph):
    FakeWorld(graph)
    launcher.start(_cmd())
    commands = graph.collect(Float64MultiArray, "/forward_position_controller/commands", count=20, timeout=30)
    assert all(len(c.data) == 6 and all(math.isfinite(v) for v in c.data) for c in commands)
    (cmd,) = graph.collect(Vector3Stamped, "/plate_cmd", timeout=10, predicate=lambda m: m.vector.x != 0.0)
    assert cmd.header.frame_id == "plate_center"
    # ball held at +x, -y: the plate tilts to send it back (positive u_x, negative u_y)
    later = graph.collect(Float64MultiArray, "/forward_position_controller/commands", count=30, timeout=15)
    u_x, u_y = _kinematics().tilt_of(np.array(later[-1].data))
    assert u_x > 0.01 and u_y < -0.005


@pytest.mark.parametrize("model, says", [
    ("wrong_width.onnx", f"input width {WIDTH - 2} but the metadata names {WIDTH}"),
    ("no_metadata.onnx", "metadata lacks")])
def test_policy_node_refuses_a_model_that_does_not_fit_with_one_line(launcher, model, says):
    result = launcher.run(_cmd(f"policy_model:={DATA / model}"), timeout=60)
    assert result.returncode != 0
    lines = [line for line in (result.stdout + result.stderr).splitlines() if says in line]
    assert len(lines) == 1, result.stderr
