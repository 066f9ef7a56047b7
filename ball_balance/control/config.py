"""Parameter schemas of the balance controllers (one source of defaults, units, bounds) and
their conversion to the pure config dataclasses. No ROS import: the nodes declare these
schemas, the benchmark validates the same YAML values with `validate`.

Runtime-changeable (through `ros2 param set`): the PID gains and the reference_* parameters;
everything else is read once at start-up.
"""
from __future__ import annotations

from typing import Any, Mapping

from ball_balance.control.estimation import EstimatorConfig
from ball_balance.control.kinematics import Chain, PlateKinematics, ShaperConfig
from ball_balance.control.mpc import MpcConfig
from ball_balance.control.pid import PidGains
from ball_balance.control.pipeline import PipelineConfig
from ball_balance.control.references import KINDS, Delayed, Reference, make_reference
from ball_balance.control.safety import SafetyConfig
from ball_balance.plate_geometry import GRAVITY_M_S2, PLATE_SIDE_M, ROLLING_FACTOR_SHELL
from ball_balance.robot import HOME_POSITIONS_RAD
from controller_manager_py.parameters import Param


def _pair(value) -> str | None:
    return None if len(value) == 2 else "must have 2 elements [x, y]"


def _six(value) -> str | None:
    return None if len(value) == 6 else "must have 6 elements (one per joint)"


REFERENCE_SCHEMA = [
    Param("reference_kind", "stationary", "what the ball tracks", choices=KINDS, user_facing=True),
    Param("reference_radius_m", 0.10, "circle/figure-eight radius, square half side, step amplitude", "m",
          0.0, 0.2, user_facing=True),
    Param("reference_period_s", 10.0, "one lap (circle, figure-eight, square) or 5 steps", "s", 0.5, 600.0,
          user_facing=True),
    Param("reference_centre_m", [0.0, 0.0], "centre of the reference, plate frame [x, y]", "m", check=_pair,
          user_facing=True),
    Param("reference_csv_path", "", "CSV path t_s,x_m,y_m (reference_kind=csv)", user_facing=True),
    Param("reference_start_delay_s", 0.0, "hold the centre this long after engaging, then start", "s",
          0.0, 600.0),
    Param("reference_blend_s", 2.0, "blend from the centre into the path over this long (no jump)", "s",
          0.0, 60.0),
]

PID_GAINS_SCHEMA = [
    Param("kp", PidGains.kp, "proportional gain", "rad/m", 0.0, 20.0, user_facing=True),
    Param("ki", PidGains.ki, "integral gain (0: none; the tracker's disturbance state removes a constant "
          "offset)", "rad/(m s)", 0.0, 20.0),
    Param("kd", PidGains.kd, "derivative gain on the measured velocity", "rad/(m/s)", 0.0, 20.0, user_facing=True),
    Param("i_limit_rad", PidGains.i_limit_rad, "clamp on ki*integral", "rad", 0.0, 0.5),
    Param("antiwindup_time_s", PidGains.antiwindup_time_s, "back-calculation time constant", "s", 0.0, 10.0),
    Param("derivative_filter_s", PidGains.derivative_filter_s, "time constant of a first-order low-pass on the "
          "velocity error of the D term (0: off)", "s", 0.0, 1.0),
]

MPC_SCHEMA = [
    Param("mpc_horizon", MpcConfig.horizon, "prediction horizon N (steps of one control period)", "", 2, 200,
          read_only=True, user_facing=True),
    Param("mpc_q_pos", MpcConfig.q_pos, "weight on position error", "1/m^2", 0.0, 1e6, read_only=True),
    Param("mpc_q_vel", MpcConfig.q_vel, "weight on velocity error", "1/(m/s)^2", 0.0, 1e6, read_only=True),
    Param("mpc_r_u", MpcConfig.r_u, "weight on tilt minus feed-forward", "1/rad^2", 1e-6, 1e6, read_only=True),
    Param("mpc_r_du", MpcConfig.r_du, "weight on tilt change per step", "1/rad^2", 0.0, 1e6, read_only=True),
    Param("max_tilt_rate_rad_s", MpcConfig.du_max_rad_s, "tilt-rate constraint", "rad/s", 0.01, 20.0,
          read_only=True),
]

COMMON_SCHEMA = [
    Param("control_rate_hz", 50.0, "control tick rate", "Hz", 5.0, 500.0, read_only=True, user_facing=True),
    Param("rolling_factor", ROLLING_FACTOR_SHELL, "k in x'' = k g sin(tilt): 0.6 shell, 0.714 solid", "",
          0.1, 1.0, read_only=True, user_facing=True),
    Param("gravity_m_s2", GRAVITY_M_S2, "g", "m/s^2", 0.1, 30.0, read_only=True),
    Param("max_tilt_cmd_rad", 0.15, "per-axis tilt command limit (controller output clip)", "rad", 0.0, 0.35,
          read_only=True, user_facing=True),
    Param("max_total_tilt_rad", 0.20, "limit on the plate's total tilt from home", "rad", 0.0, 0.5,
          read_only=True),
    Param("latency_compensation", True, "predict the ball state over the measured delay", read_only=True),
    Param("actuation_delay_s", 0.03, "command -> plate tilt delay added to the measured age (initial value "
          "when estimate_actuation_delay)", "s", 0.0, 0.5, read_only=True),
    Param("estimate_actuation_delay", True, "refine actuation_delay_s online: commanded vs measured tilt "
          "(FK of /joint_states)", read_only=True),
    Param("actuation_delay_min_window_s", 0.6, "commands stored before the delay estimate starts (it then "
          "uses the window filled so far, up to 3 s)", "s", 0.1, 3.0, read_only=True),
    Param("adapt_plant_gain", EstimatorConfig.adapt_gain, "estimate the plant gain k*g online from the ball "
          "positions and the plate tilt reached (unknown gravity, ball type, friction); rolling_factor * "
          "gravity_m_s2 is the starting value", read_only=True),
    Param("adapt_disturbance", EstimatorConfig.adapt_offset, "estimate a constant disturbance acceleration "
          "online (plate not level, tilt offset) and cancel it", read_only=True),
    Param("adapt_window_s", EstimatorConfig.window_s, "ball-state window of the plant estimate's least-squares "
          "fit", "s", 0.3, 10.0, read_only=True),
    Param("adapt_time_constant_s", EstimatorConfig.tau_s, "time constant with which fits move the plant "
          "estimate", "s", 0.05, 60.0, read_only=True),
    Param("adapt_gain_min_ratio", EstimatorConfig.gain_min_ratio, "lower bound of the estimated k*g, times "
          "rolling_factor * gravity_m_s2", "", 0.05, 1.0, read_only=True),
    Param("adapt_gain_max_ratio", EstimatorConfig.gain_max_ratio, "upper bound of the estimated k*g, times "
          "rolling_factor * gravity_m_s2", "", 1.0, 10.0, read_only=True),
    Param("adapt_max_disturbance_m_s2", EstimatorConfig.offset_max_m_s2, "bound on the estimated disturbance "
          "per axis", "m/s^2", 0.0, 5.0, read_only=True),
    Param("engage_accel_m_s2", PipelineConfig.engage_accel_m_s2, "at each fresh engagement, lead the ball "
          "from where it is into the reference, no faster than this acceleration (0: the reference at once, "
          "however far the ball)", "m/s^2", 0.0, 10.0, read_only=True),
    Param("max_prediction_s", 0.5, "never extrapolate the state further than this", "s", 0.0, 1.0,
          read_only=True),
    Param("min_markers", 3, "markers needed in a frame to act when the tracker does not publish /plate_pose "
          "(its covariance, when published, decides instead: max_position_std_m)", "", 0, 4, read_only=True),
    Param("max_position_std_m", 0.005, "act only while the ball position's 1-sigma error caused by the plate "
          "pose (from /plate_pose's covariance) is within this, whatever the marker count", "m", 1e-4, 0.1,
          read_only=True),
    Param("brake_on_loss_s", 0.6, "when the ball state becomes unusable (lost, hidden, invalid), brake the "
          "ball's motion predicted from the last good state for at most this long, then level; 0: hold the "
          "last tilt until loss_hold_s ends", "s", 0.0, 5.0, read_only=True),
    Param("brake_time_constant_s", 0.2, "braking decelerates the predicted velocity v with x'' = -v / this",
          "s", 0.05, 5.0, read_only=True),
    Param("ball_state_max_age_s", 0.25, "a ball state older than this is stale", "s", 0.01, 5.0,
          read_only=True, formerly=("stale_after_s",)),
    Param("loss_hold_s", 0.3, "hold the last tilt this long after a loss before returning home", "s", 0.0, 10.0,
          read_only=True, formerly=("grace_s",)),
    Param("healthy_before_engage_s", 0.1, "a state must stay healthy this long before holding turns back to "
          "engaged (hysteresis)", "s", 0.0, 5.0, read_only=True, formerly=("recover_s",)),
    Param("max_stamp_ahead_s", 0.2, "a ball state stamped further than this ahead of our clock is refused "
          "(under use_sim_time this node's clock trails /clock by up to ~0.15 s on a busy machine)",
          "s", 0.0, 1.0, read_only=True, formerly=("future_tolerance_s",)),
    Param("max_ball_speed_m_s", 2.0, "a ball state faster than this is refused", "m/s", 0.1, 20.0, read_only=True),
    Param("max_ball_jump_m", 0.03, "a ball state further than this from where the last accepted state, moving "
          "at its velocity, puts the ball is refused (until 3 in a row agree: a re-acquisition)", "m", 0.001, 1.0,
          read_only=True),
    Param("joint_states_timeout_s", 1.0, "no /joint_states (or, under use_sim_time, no /clock progress) for this "
          "long: stop commanding until they return", "s", 0.05, 60.0, read_only=True,
          formerly=("peer_timeout_s",)),
    Param("control_trigger", "ball_state", "'ball_state': one step per new ball state as it arrives (no wait "
          "for a tick; control_rate_hz must equal the camera rate, the pipeline assumes 1/control_rate_hz per "
          "step), the timer then steps only while states are missing; 'timer': a step every control_rate_hz "
          "tick on the newest state", choices=("ball_state", "timer"), read_only=True),
    Param("home_tolerance_rad", 0.01, "max joint error to count as at home", "rad", 1e-4, 0.5, read_only=True),
    Param("home_positions_rad", list(HOME_POSITIONS_RAD), "home joint positions (plate level)", "rad",
          check=_six, read_only=True, user_facing=True),
    Param("ik_mode", "pivot", "'wrist': wrist joints only (plate pivots 0.11 m below its centre); "
          "'pivot': all joints, plate tilts about its own centre", choices=("wrist", "pivot"), read_only=True),
    Param("max_joint_step_rad", 0.02, "per-joint change per tick", "rad", 1e-4, 0.5, read_only=True),
    Param("joint_margin_rad", 0.05, "stay this far inside the URDF joint limits", "rad", 0.0, 1.0,
          read_only=True),
]

PID_ADAPT_SCHEMA = [
    Param("adapt_pid_feedback", True, "with adapt_plant_gain: on a plant stronger than configured, scale the "
          "PID's feedback down by the configured over the estimated k*g (never up: on a weaker plant it keeps "
          "its tuned gains); false: the estimate sets only the feed-forward and the disturbance tilt",
          read_only=True),
]

PID_SCHEMA = COMMON_SCHEMA + REFERENCE_SCHEMA + PID_GAINS_SCHEMA + PID_ADAPT_SCHEMA
MPC_NODE_SCHEMA = COMMON_SCHEMA + REFERENCE_SCHEMA + MPC_SCHEMA
RUNTIME_PARAMETERS = {p.name for p in PID_GAINS_SCHEMA + REFERENCE_SCHEMA}


def k_g(values: Mapping[str, Any]) -> float:
    return values["rolling_factor"] * values["gravity_m_s2"]


def pid_gains(values: Mapping[str, Any]) -> PidGains:
    return PidGains(kp=values["kp"], ki=values["ki"], kd=values["kd"], u_max_rad=values["max_tilt_cmd_rad"],
                    i_limit_rad=values["i_limit_rad"], antiwindup_time_s=values["antiwindup_time_s"],
                    derivative_filter_s=values["derivative_filter_s"])


def pipeline_config(values: Mapping[str, Any], controller: str) -> PipelineConfig:
    """PipelineConfig from validated parameter values (either schema)."""
    period = 1.0 / values["control_rate_hz"]
    mpc = MpcConfig()
    if controller == "mpc":
        mpc = MpcConfig(dt_s=period, horizon=values["mpc_horizon"], q_pos=values["mpc_q_pos"],
                        q_vel=values["mpc_q_vel"], r_u=values["mpc_r_u"], r_du=values["mpc_r_du"],
                        u_max_rad=values["max_tilt_cmd_rad"], du_max_rad_s=values["max_tilt_rate_rad_s"],
                        k_g=k_g(values))
    return PipelineConfig(
        controller=controller, k_g=k_g(values), control_period_s=period,
        latency_compensation=values["latency_compensation"], actuation_delay_s=values["actuation_delay_s"],
        estimate_delay=values["estimate_actuation_delay"],
        delay_min_window_s=values["actuation_delay_min_window_s"],
        max_prediction_s=values["max_prediction_s"], engage_accel_m_s2=values["engage_accel_m_s2"],
        max_tilt_rad=values["max_tilt_cmd_rad"], brake_on_loss_s=values["brake_on_loss_s"],
        brake_time_constant_s=values["brake_time_constant_s"],
        pid=pid_gains(values) if controller == "pid" else PidGains(),
        mpc=mpc,
        safety=SafetyConfig(min_markers=values["min_markers"], ball_state_max_age_s=values["ball_state_max_age_s"],
                            max_position_std_m=values["max_position_std_m"],
                            healthy_before_engage_s=values["healthy_before_engage_s"],
                            max_late_s=values["max_prediction_s"],
                            loss_hold_s=values["loss_hold_s"], home_tolerance_rad=values["home_tolerance_rad"],
                            plate_half_side_m=PLATE_SIDE_M / 2.0),
        estimator=estimator_config(values),
        law_params=dict(values))


def estimator_config(values: Mapping[str, Any]) -> EstimatorConfig:
    return EstimatorConfig(adapt_gain=values["adapt_plant_gain"], adapt_offset=values["adapt_disturbance"],
                           window_s=values["adapt_window_s"], tau_s=values["adapt_time_constant_s"],
                           gain_min_ratio=values["adapt_gain_min_ratio"],
                           gain_max_ratio=values["adapt_gain_max_ratio"],
                           offset_max_m_s2=values["adapt_max_disturbance_m_s2"])


def shaper_config(values: Mapping[str, Any]) -> ShaperConfig:
    return ShaperConfig(max_joint_step_rad=values["max_joint_step_rad"], max_tilt_rad=values["max_total_tilt_rad"],
                        joint_margin_rad=values["joint_margin_rad"])


def reference(values: Mapping[str, Any]) -> Reference:
    """The reference the parameters describe (ReferenceError names the problem)."""
    centre = tuple(values["reference_centre_m"])
    inner = make_reference(values["reference_kind"], values["reference_radius_m"], values["reference_period_s"],
                           centre, values["reference_csv_path"])
    delay, blend = values["reference_start_delay_s"], values["reference_blend_s"]
    return Delayed(inner, delay, centre, blend) if delay > 0 or blend > 0 else inner


def plate_kinematics(chain: Chain, values: Mapping[str, Any]) -> PlateKinematics:
    return PlateKinematics(chain, values["home_positions_rad"], shaper=shaper_config(values), mode=values["ik_mode"])
