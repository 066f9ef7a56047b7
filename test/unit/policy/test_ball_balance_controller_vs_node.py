"""The policy inside the controller manager against the policy node (no ROS graph):

1. fed the same ball states and measured joints at the same ticks, BallBalanceController and
   the node's control step (its pipeline, observation and age rule) give the policy the same
   observation vectors, the same tilts and the same joint targets (to 1e-6);
2. every target a step computes reaches the hardware: the controller writes it every manager
   cycle, moved within the URDF velocity limits, so the manager's limits stage (which writes
   its saturated value back, as ros2_control's does) never cuts a step short;
3. lock-stepped in the MuJoCo arm, the in-manager controller is as smooth as the node's path
   (pipeline at the policy's rate -> forward_position_controller). Before 2 was fixed the
   manager's stage cut each (then 50 Hz) step to 6.3 mrad: tilt-rate RMS 5.2 rad/s against 0.6
   for the node's path.
"""
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
from ball_tracker_msgs.msg import BallState

from ball_balance.control import config as control_config
from ball_balance.control.kinematics import Chain
from ball_balance.controllers.ball_balance_controller import NODE_ONLY, BallSample
from ball_balance.nodes.balance_node_base import BalanceControllerNode
from ball_balance.policy.params import POLICY_SCHEMA
from ball_balance.robot import JOINT_NAMES, robot_description, robot_description_path
from controller_manager_py.manager.controller_manager import ControllerManager

ROOT = Path(__file__).resolve().parents[3]
PLUGIN = "ball_balance_controllers/BallBalanceController"
MANAGER_HZ, CAMERA_HZ = 500, 60
DT = 1.0 / MANAGER_HZ


def section(path: str, name: str) -> dict:
    return yaml.safe_load((ROOT / path).read_text())[name]["ros__parameters"]


CONTROL_HZ = section("config/ur_controllers_policy.yaml", "ball_balance_controller")["control_rate_hz"]


def controller_values(**kw) -> dict:
    values = {k: v for k, v in section("config/ur_controllers_policy.yaml", "ball_balance_controller").items()
              if k not in NODE_ONLY}
    values.update(async_step=False)   # the step inline: deterministic
    values.update(kw)
    return values


def activated(cm: ControllerManager, name: str, plugin: str, values: dict):
    """Load, configure and activate a controller in cm; the controller instance."""
    cm.load_controller(name, plugin, values)
    cm.configure_controller(name)
    cm.switch_controller([name], [], 2)
    return cm.controllers[name].c


def node_pipeline():
    """The pipeline ball_balance_policy builds: its schema's defaults, config/policy.yaml, its
    own make_pipeline() and the node's URDF."""
    params = {p.name: p.default for p in POLICY_SCHEMA}
    params.update(section("config/policy.yaml", "ball_balance_policy"))
    chain = Chain.from_urdf(robot_description_path().read_text(), JOINT_NAMES)
    node = SimpleNamespace(params=params, kinematics=control_config.plate_kinematics(chain, params),
                           CONTROLLER="policy")
    return BalanceControllerNode.make_pipeline(node)


def recording(runner, observations: list):
    infer = runner.infer

    def infer_and_record(obs):
        observations.append(np.array(obs, dtype=float))
        return infer(obs)
    return infer_and_record


def ball_at(t: float) -> BallSample:
    """A ball rolling across the plate (plate frame, m and m/s), stamped at t."""
    x, y = 0.06 * math.cos(1.3 * t), -0.04 + 0.03 * math.sin(0.9 * t)
    return BallSample(x, y, -0.078 * math.sin(1.3 * t), 0.027 * math.cos(0.9 * t), True, 4, t)


def test_the_controller_and_the_node_give_the_policy_the_same_observations_tilts_and_targets():
    cm = ControllerManager(MANAGER_HZ)
    cm.load_robot_description(robot_description("mock"))
    ctrl = activated(cm, "ball", PLUGIN, controller_values())
    seen_by_controller, seen_by_node = [], []
    ctrl.pipeline.law.runner.infer = recording(ctrl.pipeline.law.runner, seen_by_controller)
    steps = []   # what each controller step was given and gave: (time, q measured, ball, u, target)
    step = ctrl._step

    def recorded_step(time, period):
        q, _ = ctrl._step_in
        ball = ctrl._ball
        result = step(time, period)
        steps.append((time, q, ball, ctrl.u, ctrl._target.copy()))
        return result
    ctrl._step = recorded_step

    t, next_frame = 0.0, 0.0
    for _ in range(4 * MANAGER_HZ):                      # 4 s: homing, ready, engaged with the policy
        t += DT
        if t >= next_frame - 1e-9 and t > 0.5:
            next_frame = t + 1.0 / CAMERA_HZ
            ctrl.offer_ball_state(ball_at(t), t)
        cm.cycle(t, DT)
    assert len(steps) == pytest.approx(4 * CONTROL_HZ, abs=1)
    assert len(seen_by_controller) > 100                  # the policy ran for most of it

    # the node: its pipeline stepped at the same ticks on the same states (ROS times in ns)
    pipeline = node_pipeline()
    pipeline.law.runner.infer = recording(pipeline.law.runner, seen_by_node)
    for time, q, ball, u, target in steps:
        now_s = round(time * 1e9) * 1e-9
        obs = None
        if ball is not None:
            msg = BallState(x=ball.x, y=ball.y, vx=ball.vx, vy=ball.vy, tracking_valid=ball.valid,
                            markers_found=ball.markers)
            stamp_ns = round(ball.stamp_s * 1e9)
            msg.header.stamp.sec, msg.header.stamp.nanosec = stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000
            obs = BalanceControllerNode._observation(msg, max(0.0, now_s - stamp_ns * 1e-9), 0.0)
        result = pipeline.step(now_s, obs, q)
        np.testing.assert_allclose(result.u, u, atol=1e-6, err_msg=f"tilt at t={time:.3f} s")
        np.testing.assert_allclose(result.q_cmd, target, atol=1e-6, err_msg=f"joint target at t={time:.3f} s")
    assert len(seen_by_node) == len(seen_by_controller)
    for k, (mine, theirs) in enumerate(zip(seen_by_controller, seen_by_node)):
        np.testing.assert_allclose(mine, theirs, atol=1e-6, err_msg=f"observation of inference {k}")


def test_every_step_target_reaches_the_hardware_and_the_manager_stage_never_clamps():
    cm = ControllerManager(MANAGER_HZ)
    cm.load_robot_description(robot_description("mock"))
    ctrl = activated(cm, "ball", PLUGIN, controller_values())
    hardware = cm.rm.command_interfaces
    vmax = 3.14   # rad/s, the URDF velocity limit of every UR joint
    t, previous = 0.0, None
    before_steps = []   # at each step: (its previous target far from home, that target reached)
    step = ctrl._step

    def checked_step(time, period):
        if ctrl._target is not None:   # the hardware holds what the previous cycle wrote
            written = np.array([hardware[f"{j}/position"].value for j in JOINT_NAMES])
            before_steps.append((np.max(np.abs(ctrl._target - ctrl.pipeline.kin.home_q)) > 0.02,
                                 bool(np.allclose(written, ctrl._target, atol=1e-12))))
        return step(time, period)
    ctrl._step = checked_step
    for k in range(4 * MANAGER_HZ):
        t += DT
        if k % (MANAGER_HZ // CAMERA_HZ) == 0 and t > 0.5:
            # a ball far off centre and fast: large tilt changes, steps at the shaping limit
            ctrl.offer_ball_state(BallSample(0.1 * math.cos(3 * t), 0.1 * math.sin(3 * t), -0.3 * math.sin(3 * t),
                                             0.3 * math.cos(3 * t), True, 4, t), t)
        cm.cycle(t, DT)
        written = np.array([hardware[f"{j}/position"].value for j in JOINT_NAMES])
        if previous is not None:
            assert np.max(np.abs(written - previous)) <= vmax * DT + 1e-12
        previous = written
    big_steps = sum(far for far, _ in before_steps)
    reached = sum(hit for _, hit in before_steps)
    assert big_steps > 50
    assert reached >= 4 * CONTROL_HZ - 30   # every step's target was reached before the next (homing aside)
    assert sum(comp.limiter.clamped for comp in cm.rm.components.values()) == 0


@pytest.mark.slow
def test_in_the_mujoco_arm_the_controller_is_as_smooth_as_the_nodes_path():
    """Lock-stepped (load cannot change it): truth-fed 60 Hz states, ball released at (60, -40) mm."""
    def run(in_manager: bool, seconds: float = 8.0):
        urdf = robot_description("mujoco", {"camera_enabled": "false", "truth_fed": "true", "camera_rate_hz": "60",
                                            "ball_x": "0.06", "ball_y": "-0.04", "seed": "0"})
        cm = ControllerManager(MANAGER_HZ)
        cm.load_robot_description(urdf)
        world = cm.rm.clock_component.plugin.world
        if in_manager:
            ctrl = activated(cm, "ball", PLUGIN, controller_values())
        else:
            fwd = activated(cm, "fwd", "position_controllers/JointGroupPositionController",
                            {"joints": list(JOINT_NAMES)})
            pipeline = node_pipeline()
        ball, next_frame, next_tick, u, tilts, errors = None, 0.0, 0.0, (0.0, 0.0), [], []
        while world.time_s < seconds:
            cm.cycle(cm.now(), DT)
            now = world.time_s
            if now >= next_frame - 1e-9:
                next_frame += 1.0 / CAMERA_HZ
                truth = world.ball_truth()
                x, y = world.detected_ball()
                ball = BallSample(x, y, truth.vx, truth.vy, True, 4, now)
                if in_manager:
                    ctrl.offer_ball_state(ball, now)
            if in_manager:
                u = ctrl.u
            elif now >= next_tick - 1e-9:
                next_tick += 1.0 / CONTROL_HZ
                obs = None if ball is None else BalanceControllerNode._observation(
                    BallState(x=ball.x, y=ball.y, vx=ball.vx, vy=ball.vy, tracking_valid=True, markers_found=4),
                    max(0.0, now - ball.stamp_s), 0.0)
                result = pipeline.step(now, obs, world.joint_positions())
                fwd.slot.offer([float(v) for v in result.q_cmd])
                u = result.u
            if round(now / DT) % 5 == 0:          # 100 Hz, as the live monitor samples /plate_cmd
                truth = world.ball_truth()
                tilts.append(u)
                errors.append(math.hypot(truth.x, truth.y) if now >= 5.0 else math.nan)
        assert not world.ball_dropped
        rate = np.diff(np.array(tilts), axis=0) * 100.0
        stage_clamps = sum(comp.limiter.clamped for comp in cm.rm.components.values())
        return float(np.sqrt(np.mean(rate ** 2))), float(np.sqrt(np.nanmean(np.square(errors)))), stage_clamps

    rate_manager, rmse_manager, clamps = run(in_manager=True)
    rate_node, rmse_node, _ = run(in_manager=False)
    assert clamps == 0
    assert rate_manager < 1.5 * rate_node + 0.2, (rate_manager, rate_node)
    assert rmse_manager < 1.5 * rmse_node + 0.002, (rmse_manager, rmse_node)
