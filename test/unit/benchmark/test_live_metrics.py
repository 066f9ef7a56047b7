"""The live monitor's metrics (ball_balance/benchmark/live.py) come from header stamps only: a
lock-stepped benchmark episode turned into the messages the graph would publish gives the
benchmark's own figures, in whatever order and however late the topics are read; time the
controller is not engaged counts as error against the last reference."""
import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest

from ball_balance.benchmark.episode import EpisodeSpec, Push, run_episode
from ball_balance.benchmark.live import Recording, format_metrics, live_metrics, live_series

WALL0_S = 1.7e9   # wall clock at stamp 0 (real time: the write times are the stamps + this)


def _header(t_s: float):
    sec = math.floor(t_s)
    return SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=round((t_s - sec) * 1e9)))


def truth_msg(t_s, x, y, on_plate=True):
    return SimpleNamespace(header=_header(t_s), x=x, y=y, ball_found=on_plate)


def state_msg(t_s, x, y):
    return SimpleNamespace(header=_header(t_s), x=x, y=y, tracking_valid=True, markers_found=4)


def point_msg(t_s, x, y):
    return SimpleNamespace(header=_header(t_s), point=SimpleNamespace(x=x, y=y))


def vector_msg(t_s, x, y):
    return SimpleNamespace(header=_header(t_s), vector=SimpleNamespace(x=x, y=y))


def recording(truth_s, ref_s, x=0.02, target=(0.0, 0.0)):
    """Ball at (x, 0) (a function of t or a number), target fixed, no commands."""
    rec = Recording()
    for t in truth_s:
        rec.on_truth(truth_msg(t, x(t) if callable(x) else x, 0.0))
    for t in ref_s:
        rec.on_reference(point_msg(t, *target))
    return rec


# ---- an episode of the benchmark, as the graph would publish it --------------------------
def episode_messages(series, start_s=100.0, rest_s=2.0):
    """The messages of a recorded episode (series from the engagement, EpisodeResult.series), per
    topic in publication order: before the engagement rest_s of the ball resting at the release
    with zero commands and no target; then per control tick k, at tick time tau_k = t_{k-1}
    (the truth's stamp of the step before): /plate_cmd u_k, and the target at t_k stamped t_k
    (the controller on the tick at t_k publishes it); /sim/ball_truth at t_k after the step
    (off the plate from the step the episode dropped on, and a while after it); /ball_state
    per camera frame (stamp tau_k - age_k), written just before the first command acting on
    it. Each message carries its wall write time (real time)."""
    t = start_s + rest_s + series["t"]
    dt = float(np.median(np.diff(t)))
    tau = np.concatenate([[t[0] - dt], t[:-1]])
    topics = {"truth": [], "state": [], "reference": [], "command": []}
    for t_k in np.arange(start_s, t[0] - 1e-9, 0.01):
        topics["truth"].append((truth_msg(t_k, series["x"][0], series["y"][0]), None))
    for tau_k in np.arange(start_s, tau[0] - 1e-9, dt):
        topics["command"].append((vector_msg(tau_k, 0.0, 0.0), WALL0_S + tau_k))
    frames = set()
    dropped = series["on_plate_last"] == 0.0
    for k in range(len(t)):
        frame_s = round(tau[k] - series["age"][k], 6)
        if frame_s not in frames:
            frames.add(frame_s)
            topics["state"].append((state_msg(frame_s, series["ex"][k], series["ey"][k]), WALL0_S + tau[k] - 0.0005))
        topics["command"].append((vector_msg(tau[k], series["ux"][k], series["uy"][k]), WALL0_S + tau[k] + 0.001))
        if series["mode"][k] > 0:
            topics["reference"].append((point_msg(t[k], series["rx"][k], series["ry"][k]), None))
        on_plate = not (dropped and k == len(t) - 1)
        topics["truth"].append((truth_msg(t[k], series["x"][k], series["y"][k], on_plate), None))
    # the graph goes on after the episode's end (the monitor stops reading then)
    for j in range(1, 13):
        t_k = t[-1] + j * dt
        topics["command"].append((vector_msg(t_k - dt, series["ux"][-1], series["uy"][-1]), WALL0_S + t_k - dt))
        if series["mode"][-1] > 0:
            topics["reference"].append((point_msg(t_k, series["rx"][-1], series["ry"][-1]), None))
        topics["truth"].append((truth_msg(t_k, 0.3 if dropped else series["x"][-1], series["y"][-1], not dropped),
                                None))
    return topics, frames


def feed(rec, topics, order):
    callbacks = {"truth": lambda m, w: rec.on_truth(m), "state": rec.on_state,
                 "reference": lambda m, w: rec.on_reference(m), "command": rec.on_command}
    for name in order:
        for msg, written in topics[name]:
            callbacks[name](msg, written)


def recorded_episode(spec):
    result = run_episode(dataclasses.replace(spec, record=True))
    series = dict(result.series, on_plate_last=np.array(0.0 if result.metrics["drop"] else 1.0))
    return result, series


def assert_same_figures(monitor, benchmark):
    for key in ("drop", "survived_s", "rmse_m", "rmse_steady_m", "settle_s", "peak_tilt_rad", "smoothness_rad_s",
                "engaged_frac"):
        assert monitor[key] == pytest.approx(benchmark[key], rel=1e-6, abs=1e-9, nan_ok=True), key


@pytest.mark.parametrize("order", [("truth", "state", "reference", "command"),
                                   ("reference", "command", "state", "truth")])
def test_the_monitor_gives_the_benchmarks_figures_for_the_messages_of_a_benchmark_episode(order):
    # a PID on the standard domain following the circle, 7 s lock-stepped; the topics read one
    # after the other (the target and the commands a whole run late, or early)
    result, series = recorded_episode(EpisodeSpec(controller="pid", domain="standard", reference="circle",
                                                  seed=1, duration_s=7.0))
    topics, frames = episode_messages(series)
    rec = Recording()
    feed(rec, topics, order)
    end_s = rec.t0_s + 2.0 + series["t"][-1]
    m = live_metrics(rec, end_s)
    assert m is not None
    assert_same_figures(m, result.metrics)
    assert m["drop"] == 0.0 and math.isfinite(m["settle_s"]) and m["rmse_steady_m"] < 0.002
    # camera-to-command on the stamps: each frame's stamp -> its first command's
    first_age = {}
    tau = np.concatenate([[np.nan], 102.0 + series["t"][:-1]])
    for k in range(1, len(tau)):
        if tau[k] - series["age"][k] >= 102.0:     # frames captured from the engagement on
            first_age.setdefault(round(tau[k] - series["age"][k], 6), series["age"][k])
    assert len(frames) > 150
    assert m["latency_s"] == pytest.approx(np.mean(list(first_age.values())), abs=2e-6)
    assert m["tracking_valid_fraction"] == 1.0 and m["truth_samples_missing"] == 0.0


def test_a_drop_ends_the_figures_where_the_truth_shows_the_ball_off_the_plate():
    spec = EpisodeSpec(controller="pid", domain="standard", seed=2, duration_s=4.0, events=(Push(1.0, 1.5, 0.0),))
    result, series = recorded_episode(spec)
    assert result.metrics["drop"] == 1.0
    topics, _ = episode_messages(series)
    rec = Recording()
    feed(rec, topics, ("truth", "state", "reference", "command"))
    rec.dropped = True                       # /sim/ball_dropped
    assert rec.end_s(30.0) == pytest.approx(rec.t0_s + 2.0 + series["t"][-1])
    m = live_metrics(rec, rec.end_s(30.0))
    assert_same_figures(m, result.metrics)


def test_topics_read_late_are_waited_for_not_held_over():
    # the truth has been read to 6 s, the targets only to 3 s (still queued): the recording
    # counts to 3 s, and a run of 5 s is not over until the targets reach 5 s
    steady = np.arange(0.5, 6.0, 0.02)
    rec = recording(np.arange(0.0, 6.0, 0.01), steady[steady <= 3.0], x=lambda t: 0.1 * t, target=(0.0, 0.0))
    assert rec.covered_until_s() == pytest.approx(steady[steady <= 3.0][-1])
    assert rec.end_s(5.0) == pytest.approx(5.0) and rec.covered_until_s() < rec.end_s(5.0)
    assert live_series(rec, rec.end_s(5.0))["t"][-1] == pytest.approx(rec.covered_until_s() - 0.5, abs=0.011)
    for t in steady[steady > 3.0]:
        rec.on_reference(point_msg(t, 0.0, 0.0))
    assert live_series(rec, rec.end_s(5.0))["t"][-1] == pytest.approx(4.5, abs=0.011)


def test_targets_that_stop_while_commands_go_on_count_as_not_engaged():
    rec = recording(np.arange(0.0, 4.0, 0.01), np.arange(0.5, 2.0, 0.02))
    for t in np.arange(0.0, 4.0, 1 / 60):
        rec.on_command(vector_msg(t, 0.01, 0.0))
    # no target queued behind the commands: read to the commands' stamp less the freshness
    assert rec.covered_until_s() == pytest.approx(np.arange(0.0, 4.0, 1 / 60)[-1] - 0.1)
    m = live_metrics(rec)
    assert 0.35 < m["engaged_frac"] < 0.5 and m["rmse_m"] == pytest.approx(0.02)
    assert m["peak_tilt_rad"] == pytest.approx(0.01)


def test_a_pause_in_the_reference_counts_as_not_engaged_and_as_error():
    steady = np.arange(0.5, 4.0, 0.02)
    gap = steady[(steady < 2.0) | (steady > 3.0)]    # controller went home for 1 s
    full = live_metrics(recording(np.arange(0.0, 4.0, 0.01), steady))
    paused = live_metrics(recording(np.arange(0.0, 4.0, 0.01), gap))
    assert full["engaged_frac"] == 1.0
    assert 0.6 < paused["engaged_frac"] < 0.75
    assert paused["rmse_m"] == pytest.approx(0.02) and full["rmse_m"] == pytest.approx(0.02)


def test_pushes_announced_by_the_simulation_are_timed_from_the_engagement():
    # engaged at 0.5 s; 20 mm off until 1.0 s, pushed at 1.0 s, back inside 5 mm 0.6 s later
    rec = recording(np.arange(0.0, 4.0, 0.01), np.arange(0.5, 4.0, 0.02),
                    x=lambda t: 0.0 if t < 1.0 or t >= 1.6 else 0.02)
    for t in (0.2, 1.0):                        # the one before the engagement does not count
        rec.on_pushed(vector_msg(t, 0.1, 0.0))
    m = live_metrics(rec)
    assert m["pushes"] == 1 and m["pushes_late"] == 0
    assert abs(m["push_recover_s"] - 0.6) < 0.011
    assert "push recovery mean 0.60 s, worst 0.60 s, 0 of 1 over 1 s" in format_metrics(m)


def test_force_steps_announced_by_the_simulation_are_timed_and_their_error_left_measured():
    # engaged at 0.5 s; a force on before it (not a step of the run), turned at 1.0 s: 20 mm
    # off until 1.4 s, then 1 mm off; off at 3.0 s: 10 mm off until 3.3 s, then on target
    def x(t):
        return 0.0 if t < 1.0 else 0.02 if t < 1.4 else 0.001 if t < 3.0 else 0.01 if t < 3.3 else 0.0
    rec = recording(np.arange(0.0, 5.0, 0.01), np.arange(0.5, 5.0, 0.02), x=x)
    for t in (0.2, 1.0, 3.0):
        rec.on_force(vector_msg(t, 0.001, 0.0))
    m = live_metrics(rec)
    assert m["steps"] == 2 and m["steps_unrecovered"] == 0
    assert abs(m["step_recover_max_s"] - 0.4) < 0.011
    assert m["step_steady_m"] == pytest.approx(0.001, abs=1e-6)   # the worst step's last second
    assert "force steps: worst back within 5 mm after 0.40 s, 1.0 mm left, 0 of 2 not back" in format_metrics(m)


def test_a_moving_target_is_taken_at_the_truths_instant_not_held():
    # the target moves at 0.1 m/s, published at 60 Hz; the ball sits exactly on it (sampled at
    # 100 Hz): held, the error would be up to 1.7 mm; between two targets it is the path itself
    speed_m_s = 0.1
    rec = Recording()
    refs = np.arange(0.5, 4.0, 1.0 / 60.0)
    for t in np.arange(0.0, 3.95, 0.01):
        rec.on_truth(truth_msg(t, speed_m_s * t, 0.0))
    for t in refs:
        rec.on_reference(point_msg(t, speed_m_s * t, 0.0))
    assert live_metrics(rec)["rmse_m"] < 1e-8
    # a pause in the targets is not bridged: the last target is held, as before
    paused = Recording()
    for t in np.arange(0.0, 3.95, 0.01):
        paused.on_truth(truth_msg(t, speed_m_s * t, 0.0))
    for t in refs[(refs <= 2.0) | (refs >= 3.0)]:
        paused.on_reference(point_msg(t, speed_m_s * t, 0.0))
    m = live_metrics(paused)
    assert m["engaged_frac"] < 0.9 and m["rmse_m"] > 0.01


def test_a_push_the_recording_ends_on_is_not_timed():
    rec = recording(np.arange(0.0, 4.0, 0.01), np.arange(0.5, 4.0, 0.02))   # read to 3.98 s
    for t in (1.0, 3.0, 4.5):                   # 3.0: the run stops 1 s later; 4.5: after the recording
        rec.on_pushed(vector_msg(t, 0.1, 0.0))
    assert live_metrics(rec)["pushes"] == 1


def test_camera_to_command_headlines_the_stamps_and_labels_the_wall_clock():
    # simulated time at a fifth of real time; each frame answered 10 ms of simulated time later
    rec = recording(np.arange(0.0, 4.0, 0.01), np.arange(0.5, 4.0, 1 / 60))
    for sim_s in np.arange(0.0, 4.0, 0.01):
        rec.on_clock(SimpleNamespace(clock=_header(sim_s).stamp), WALL0_S + 5.0 * sim_s)
    for frame_s in np.arange(0.5, 3.9, 1 / 30):
        rec.on_state(state_msg(frame_s, 0.0, 0.0), WALL0_S + 5.0 * (frame_s + 0.005))
        rec.on_command(vector_msg(frame_s + 0.010, 0.0, 0.0), WALL0_S + 5.0 * (frame_s + 0.010))
    m = live_metrics(rec)
    assert m["latency_s"] == pytest.approx(0.010, abs=1e-6) and m["latency_p95_s"] == pytest.approx(0.010, abs=1e-6)
    assert m["latency_wall_s"] == pytest.approx(0.050, abs=1e-5)
    assert m["real_time_factor"] == pytest.approx(0.2, rel=1e-6)
    assert "camera-to-command mean 10.0 ms, p95 10.0 ms (stamps); wall clock p95 50 ms at real-time factor 0.20" \
        in format_metrics(m)
