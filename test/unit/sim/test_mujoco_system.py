"""ball_balance/MujocoSystem driven through its lifecycle without ROS (synthetic manager calls):
interfaces, lock-step clock, servo following, refused commands, bad parameters."""
import logging
import math

import pytest

from ball_balance import robot
from controller_manager_py.hardware_interface import CallbackReturn, State, parse_control_resources, return_type
from controller_manager_py.parameters import ParameterError
from controller_manager_py.plugins import HARDWARE_GROUP, load_class

PERIOD_S = 0.002


def make_system(params=None, caplog=None):
    (info,) = parse_control_resources(robot.robot_description("mujoco", {"camera_enabled": False, **(params or {})}))
    system = load_class(HARDWARE_GROUP, "ball_balance/MujocoSystem")()
    system._attach(None, logging.getLogger("test_mujoco_system"))
    return system, system.on_init(info)


def run_cycles(system, n):
    for _ in range(n):
        t = system.now()
        assert system.read(t, PERIOD_S) == return_type.OK
        assert system.write(t, PERIOD_S) == return_type.OK


@pytest.fixture
def system():
    system, result = make_system()
    assert result == CallbackReturn.SUCCESS
    assert system.on_configure(State.UNCONFIGURED) == CallbackReturn.SUCCESS
    assert system.on_activate(State.INACTIVE) == CallbackReturn.SUCCESS
    yield system
    system.on_shutdown(State.ACTIVE)


def test_exports_joint_ball_and_speed_scaling_interfaces(system):
    for joint in robot.JOINT_NAMES:
        assert f"{joint}/position" in system.command_handles
        for itf in ("position", "velocity", "effort"):
            assert f"{joint}/{itf}" in system.state_handles
    assert system.get_state("speed_scaling/speed_scaling_factor") == 1.0
    assert {f"ball/{k}" for k in ("x", "y", "vx", "vy", "dropped")} <= set(system.state_handles)
    assert system.provides_clock


def test_lockstep_clock_advances_one_period_per_cycle(system):
    start = system.now()
    run_cycles(system, 50)
    assert system.now() - start == pytest.approx(50 * PERIOD_S)


def test_activation_holds_the_current_pose_and_commands_move_the_arm(system):
    assert [system.get_command(f"{j}/position") for j in robot.JOINT_NAMES] == pytest.approx(
        list(robot.HOME_POSITIONS_RAD))
    system.set_command("wrist_2_joint/position", robot.HOME_POSITIONS_RAD[4] + 0.05)
    run_cycles(system, 100)
    assert system.get_state("wrist_2_joint/position") == pytest.approx(robot.HOME_POSITIONS_RAD[4] + 0.05, abs=1e-3)
    assert system.get_state("shoulder_pan_joint/position") == pytest.approx(0.0, abs=1e-4)


@pytest.mark.parametrize("bad", [math.inf, -math.inf, 7.0])
def test_non_finite_or_out_of_limit_command_is_refused_and_counted(system, bad):
    run_cycles(system, 5)
    system.set_command("wrist_1_joint/position", bad)
    run_cycles(system, 20)
    assert system.commands_refused == 20
    assert system.get_state("wrist_1_joint/position") == pytest.approx(robot.HOME_POSITIONS_RAD[3], abs=1e-4)


def test_no_command_yet_keeps_the_target(system):
    for joint in robot.JOINT_NAMES:
        system.set_command(f"{joint}/position", math.nan)
    run_cycles(system, 20)
    assert system.commands_refused == 0
    assert system.get_state("elbow_joint/position") == pytest.approx(robot.HOME_POSITIONS_RAD[2], abs=1e-4)


def test_ball_states_follow_the_ball(system):
    system.world.place_ball(0.05, -0.02)
    run_cycles(system, 1)
    assert (system.get_state("ball/x"), system.get_state("ball/y")) == pytest.approx((0.05, -0.02), abs=1e-3)
    assert system.get_state("ball/dropped") == 0.0


@pytest.mark.parametrize("params,message", [
    ({"camera_width": 0}, "camera_width"),
    ({"camera_height": "0"}, "camera_height"),
    ({"domain": "moon"}, "unknown domain"),
    ({"warp_speed": 9}, "unknown parameter"),
    ({"pacing": "fast"}, "pacing"),
    ({"gravity_scale": "heavy"}, "gravity_scale"),
    ({"robot_description_file": "/nonexistent.urdf"}, "cannot read"),
    ({"ball_force_deg": "12"}, "ball_force_deg"),
    ({"ball_force_dir_deg": "nan"}, "ball_force_dir_deg"),
    ({"plate_mount_tilt_deg": "11"}, "plate_mount_tilt_deg"),
    ({"plate_mount_axis_deg": "-90"}, "plate_mount_axis_deg"),
])
def test_bad_hardware_parameter_fails_on_init_naming_it(params, message, caplog):
    with caplog.at_level(logging.ERROR):
        _, result = make_system(params)
    assert result == CallbackReturn.ERROR
    assert message in caplog.text


def test_description_without_plate_link_fails_on_init(tmp_path, caplog):
    text = robot.robot_description().replace('"plate_center"', '"tray"')
    path = tmp_path / "no_plate.urdf"
    path.write_text(text)
    with caplog.at_level(logging.ERROR):
        _, result = make_system({"robot_description_file": str(path)})
    assert result == CallbackReturn.ERROR
    assert "plate_center" in caplog.text


def test_domain_and_knob_overrides_reach_the_world():
    system, result = make_system({"domain": "high_gravity", "ball_mass_kg": "0.004", "seed": 3,
                                  "plate_mount_tilt_deg": "2", "plate_mount_axis_deg": "30"})
    assert result == CallbackReturn.SUCCESS
    assert system.world.knobs.gravity_scale == 1.5 and system.world.knobs.ball_mass_kg == 0.004
    assert (system.world.knobs.plate_mount_tilt_deg, system.world.knobs.plate_mount_axis_deg) == (2.0, 30.0)
    normal = system.world.plate_pose()[1][:, 2]
    assert math.degrees(math.acos(normal[2])) == pytest.approx(2.0, abs=1e-6)


class _WallClock:
    """A wall clock the test moves by hand, so pacing is checked without depending on how
    busy the machine is (a real sleep can overshoot by tens of ms on two busy cores)."""

    def __init__(self):
        import time

        self._time, self.now_s = time, 1000.0

    def monotonic(self):
        return self.now_s

    def __getattr__(self, name):
        return getattr(self._time, name)


def test_realtime_pacing_follows_the_wall_clock(monkeypatch):
    from ball_balance.hardware import mujoco_system

    wall = _WallClock()
    monkeypatch.setattr(mujoco_system, "_time", wall)
    system, result = make_system({"pacing": "realtime"})
    assert result == CallbackReturn.SUCCESS
    system.on_configure(State.UNCONFIGURED)
    system.on_activate(State.INACTIVE)
    system.read(system.now(), PERIOD_S)
    sim_start, wall_start = system.now(), wall.now_s
    for _ in range(75):  # 0.3 s of cycles 4 ms apart
        wall.now_s += 0.004
        system.read(system.now(), PERIOD_S)
    assert system.now() - sim_start == pytest.approx(wall.now_s - wall_start, abs=2 * PERIOD_S)
    assert system.overruns == 0


def test_realtime_pacing_skips_a_long_stall_instead_of_spiralling(monkeypatch):
    """After a 200 ms stall the simulation catches up at most 50 ms and re-anchors (counted),
    rather than running hundreds of physics steps in one cycle."""
    from ball_balance.hardware import mujoco_system

    wall = _WallClock()
    monkeypatch.setattr(mujoco_system, "_time", wall)
    system, _ = make_system({"pacing": "realtime"})
    system.on_configure(State.UNCONFIGURED)
    system.on_activate(State.INACTIVE)
    system.read(system.now(), PERIOD_S)
    before = system.now()
    wall.now_s += 0.2
    system.read(system.now(), PERIOD_S)
    assert system.now() - before == pytest.approx(0.05, abs=2 * PERIOD_S)
    assert system.overruns == 1
    wall.now_s += 0.004  # then it follows the wall clock again from the new anchor
    later = system.now()
    system.read(system.now(), PERIOD_S)
    assert system.now() - later == pytest.approx(0.004, abs=PERIOD_S)


def test_without_sim_time_the_manager_keeps_its_clock():
    system, result = make_system({"sim_time": False})
    assert result == CallbackReturn.SUCCESS and not system.provides_clock


def test_initial_speed_scaling_factor_slows_the_joints(caplog):
    param = '<param name="initial_speed_scaling_factor">'
    text = robot.robot_description("mujoco", {"camera_enabled": False}).replace(f"{param}1<", f"{param}0.5<")
    (info,) = parse_control_resources(text)
    system = load_class(HARDWARE_GROUP, "ball_balance/MujocoSystem")()
    system._attach(None, logging.getLogger("test_mujoco_system"))
    assert system.on_init(info) == CallbackReturn.SUCCESS
    system.on_configure(State.UNCONFIGURED)
    system.on_activate(State.INACTIVE)
    assert system.get_state("speed_scaling/speed_scaling_factor") == 0.5
    system.set_command("wrist_3_joint/position", 1.0)
    peak = 0.0
    for _ in range(150):
        run_cycles(system, 1)
        peak = max(peak, abs(system.get_state("wrist_3_joint/velocity")))
    assert 0.5 * 3.14 * 0.9 < peak <= 0.5 * 3.14 * 1.05

    bad = text.replace('">0.5<', '">0<')
    (info,) = parse_control_resources(bad)
    system = load_class(HARDWARE_GROUP, "ball_balance/MujocoSystem")()
    system._attach(None, logging.getLogger("test_mujoco_system"))
    with caplog.at_level(logging.ERROR):
        assert system.on_init(info) == CallbackReturn.ERROR
    assert "initial_speed_scaling_factor" in caplog.text


def test_pause_stops_the_clock_and_steps_advance_it_exactly(system):
    run_cycles(system, 5)
    pause = system.request_pause(True)
    assert not pause.done()   # the loop takes it at its next read()
    run_cycles(system, 1)
    paused_at = system.now()
    assert pause.result(0) == paused_at
    run_cycles(system, 20)
    assert system.now() == paused_at
    steps = system.request_steps(7)
    run_cycles(system, 3)
    dt = system.world.physics_dt_s
    assert system.now() == pytest.approx(paused_at + 7 * dt)
    assert steps.result(0) == (paused_at, system.now())
    system.request_pause(False)
    run_cycles(system, 10)
    assert system.now() == pytest.approx(paused_at + 7 * dt + 10 * PERIOD_S)


def test_steps_asked_for_before_a_resume_are_answered_not_taken(system):
    system.request_pause(True)
    run_cycles(system, 1)
    steps = system.request_steps(5)
    system.request_pause(False)
    run_cycles(system, 1)
    assert steps.result(0) is None


def test_steps_that_reach_a_running_loop_are_answered_not_taken(system):
    system.request_pause(True)
    system.request_pause(False)   # another caller resumes before the steps arrive
    steps = system.request_steps(5)
    run_cycles(system, 1)
    start = system.now()
    assert steps.result(0) is None
    run_cycles(system, 3)
    assert system.now() == pytest.approx(start + 3 * PERIOD_S)   # running as before, no extra steps


def test_start_paused_waits_for_resume_with_the_ball_where_it_was_placed():
    system, result = make_system({"start_paused": True, "domain": "pushes", "ball_x": 0.05})
    assert result == CallbackReturn.SUCCESS
    try:
        assert system.on_configure(State.UNCONFIGURED) == CallbackReturn.SUCCESS
        assert system.on_activate(State.INACTIVE) == CallbackReturn.SUCCESS
        start = system.now()
        run_cycles(system, 3000)   # 6 s of the manager's cycles: past the domain's first push (4 s)
        assert system.now() == start
        assert (system.get_state("ball/x"), system.get_state("ball/vx")) == pytest.approx((0.05, 0.0), abs=1e-6)
        system.request_pause(False)
        run_cycles(system, 10)
        assert system.now() == pytest.approx(start + 10 * PERIOD_S)
    finally:
        system.on_shutdown(State.ACTIVE)


def test_reset_world_puts_arm_and_ball_back_at_rest(system):
    system.set_command("wrist_2_joint/position", robot.HOME_POSITIONS_RAD[4] + 0.1)
    system.request_push((0.1, 0.0, 0.0))
    run_cycles(system, 100)
    assert abs(system.get_state("ball/x")) > 0.01
    assert system.get_state("wrist_2_joint/position") > robot.HOME_POSITIONS_RAD[4] + 0.05
    system.request_reset_world()
    for joint, q in zip(robot.JOINT_NAMES, robot.HOME_POSITIONS_RAD, strict=True):
        system.set_command(f"{joint}/position", q)
    run_cycles(system, 1)
    assert system.get_state("wrist_2_joint/position") == pytest.approx(robot.HOME_POSITIONS_RAD[4], abs=1e-3)
    assert system.get_state("ball/x") == pytest.approx(0.0, abs=1e-3)
    assert abs(system.get_state("ball/vx")) < 0.01


def test_push_and_timed_wrench_move_the_ball(system):
    system.request_push((0.0, 0.1, 0.0))
    run_cycles(system, 50)
    assert system.get_state("ball/vy") == pytest.approx(0.1, rel=0.05)
    system.request_reset_world()
    run_cycles(system, 1)
    mass = system.world.knobs.ball_mass_kg
    system.request_wrench((0.01, 0.0, 0.0), (0.0, 0.0, 0.0), 0.05, True)
    run_cycles(system, 100)   # 0.2 s: the force acted for 0.05 s of it
    expected = system.world.config.rolling_factor * 0.01 * 0.05 / mass
    assert system.get_state("ball/vx") == pytest.approx(expected, rel=0.1)


def test_pushes_domain_pushes_the_ball_in_the_hosted_simulation():
    system, result = make_system({"domain": "pushes"})
    assert result == CallbackReturn.SUCCESS
    system.on_configure(State.UNCONFIGURED)
    system.on_activate(State.INACTIVE)
    run_cycles(system, int(3.9 / PERIOD_S))
    assert abs(system.get_state("ball/vx")) + abs(system.get_state("ball/vy")) < 0.01
    run_cycles(system, int(0.2 / PERIOD_S))   # the first push at 4 s
    speed = (system.get_state("ball/vx") ** 2 + system.get_state("ball/vy") ** 2) ** 0.5
    assert speed == pytest.approx(0.15, rel=0.1)
    system.on_shutdown(State.ACTIVE)


def _ball_velocity(system):
    return system.get_state("ball/vx"), system.get_state("ball/vy")


def _tilt_speed(system, tilt_deg, seconds):
    """The speed a plate tilted by tilt_deg gives the ball in `seconds`: k g sin(tilt) t."""
    gravity = 9.81 * system.world.knobs.gravity_scale
    return system.world.config.rolling_factor * gravity * math.sin(math.radians(tilt_deg)) * seconds


def test_ball_force_from_the_start_and_changed_while_running():
    system, result = make_system({"ball_force_deg": "2", "ball_force_dir_deg": "90"})
    assert result == CallbackReturn.SUCCESS
    system.on_configure(State.UNCONFIGURED)
    system.on_activate(State.INACTIVE)
    try:
        run_cycles(system, 100)    # 0.2 s towards +y
        vx, vy = _ball_velocity(system)
        assert vy == pytest.approx(_tilt_speed(system, 2.0, 0.2), rel=0.1) and abs(vx) < 1e-3
        said = system.ball_force_words(1.0, 180.0)
        assert "180 deg" in said and "1 deg" in said
        asked_s, taken = system.now(), system.request_ball_force(1.0, 180.0)
        run_cycles(system, 1)
        assert taken.result(0) == asked_s   # applied at the start of the next read(), before its steps
        run_cycles(system, 100)    # the y speed kept, -x gained at half the rate
        vx, vy2 = _ball_velocity(system)
        assert vx == pytest.approx(-_tilt_speed(system, 1.0, 0.2), rel=0.1) and vy2 == pytest.approx(vy, rel=0.05)
        system.request_reset_world()   # the force is a setting of the world: it stays
        run_cycles(system, 100)
        vx, vy = _ball_velocity(system)
        assert vx == pytest.approx(-_tilt_speed(system, 1.0, 0.2), rel=0.1) and abs(vy) < 1e-3
        assert system.ball_force_words(0.0, 0.0) == "no ball force"
        system.request_ball_force(0.0, 0.0)
        run_cycles(system, 50)
        assert _ball_velocity(system)[0] == pytest.approx(vx, rel=0.05)
    finally:
        system.on_shutdown(State.ACTIVE)


@pytest.mark.parametrize("tilt, direction, name", [(10.5, 0.0, "ball_force_deg"), (math.nan, 0.0, "ball_force_deg"),
                                                   (-1.0, 0.0, "ball_force_deg"), (1.0, math.inf, "ball_force_dir_deg"),
                                                   (1.0, 400.0, "ball_force_dir_deg")])
def test_a_bad_ball_force_request_is_refused_naming_the_value_and_changes_nothing(system, tilt, direction, name):
    system.request_ball_force(1.0, 0.0)
    with pytest.raises(ParameterError, match=name):
        system.request_ball_force(tilt, direction)
    run_cycles(system, 100)
    assert system.ball_force == (1.0, 0.0)
    assert system.get_state("ball/vx") == pytest.approx(_tilt_speed(system, 1.0, 0.2), rel=0.1)


def test_force_domain_steps_in_the_hosted_simulation_as_in_an_episode():
    system, result = make_system({"domain": "force_3deg", "seed": 2})
    assert result == CallbackReturn.SUCCESS
    system.on_configure(State.UNCONFIGURED)
    system.on_activate(State.INACTIVE)
    try:
        run_cycles(system, int(4.9 / PERIOD_S))
        assert max(map(abs, _ball_velocity(system))) < 1e-3
        run_cycles(system, int(0.4 / PERIOD_S))    # on at 5 s, towards force_step_dir_deg
        vx, vy = _ball_velocity(system)
        direction = math.radians(system.world.knobs.force_step_dir_deg)
        assert math.hypot(vx, vy) == pytest.approx(_tilt_speed(system, 3.0, 0.3), rel=0.15)
        assert vx * math.cos(direction) + vy * math.sin(direction) > 0.95 * math.hypot(vx, vy)
    finally:
        system.on_shutdown(State.ACTIVE)


class AnnouncedForces:
    """The ROS side, reduced to what /sim/ball_force carries: (stamp s, fx N, fy N) per change."""

    def __init__(self):
        self.forces = []

    def publish_force(self, time_s, fx_n, fy_n):
        self.forces.append((time_s, fx_n, fy_n))

    def __getattr__(self, name):   # every other publisher and hook: nothing to see here
        return lambda *args, **kwargs: None


def test_every_change_of_the_force_on_the_ball_is_announced_when_it_acts():
    system, result = make_system({"domain": "force_3deg", "seed": 2, "ball_force_deg": "1"})
    assert result == CallbackReturn.SUCCESS
    system.ros = announced = AnnouncedForces()
    system.on_configure(State.UNCONFIGURED)
    system.on_activate(State.INACTIVE)
    try:
        held = system.world.knobs.tilt_force_n(1.0, 0.0)
        step = system.world.knobs.tilt_force_n(3.0, system.world.knobs.force_step_dir_deg)
        turned = system.world.knobs.tilt_force_n(3.0, system.world.knobs.force_step_dir_deg + 90.0)
        run_cycles(system, int(13.01 / PERIOD_S))
        system.request_reset_world()        # holds the same force again: no change
        run_cycles(system, 1)
        system.request_ball_force(0.0, 0.0)
        run_cycles(system, 1)
        stamps = [t for t, _, _ in announced.forces]
        # configured, the step on, turned, off, the held force ended: each once, as it acts
        assert stamps == pytest.approx([0.0, 5.0, 9.0, 13.0, 13.014], abs=PERIOD_S + 1e-9)
        expected = [held, tuple(map(sum, zip(held, step))), tuple(map(sum, zip(held, turned))), held, (0.0, 0.0)]
        for (_, fx, fy), (ex, ey) in zip(announced.forces, expected, strict=True):
            assert (fx, fy) == pytest.approx((ex, ey), abs=1e-9)
    finally:
        system.on_shutdown(State.ACTIVE)


def test_a_reset_of_the_world_during_a_force_step_announces_its_end():
    system, result = make_system({"domain": "force_3deg", "seed": 2})
    assert result == CallbackReturn.SUCCESS
    system.ros = announced = AnnouncedForces()
    system.on_configure(State.UNCONFIGURED)
    system.on_activate(State.INACTIVE)
    try:
        run_cycles(system, int(5.5 / PERIOD_S))
        system.request_reset_world()        # the world drops the step's force with the others
        run_cycles(system, 1)
        (_, _, _), (on_s, _, _), (end_s, fx, fy) = announced.forces   # configured, on, reset
        assert on_s == pytest.approx(5.0, abs=PERIOD_S) and end_s == pytest.approx(5.5, abs=PERIOD_S)
        assert (fx, fy) == (0.0, 0.0)
    finally:
        system.on_shutdown(State.ACTIVE)
