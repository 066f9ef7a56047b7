"""Live-graph metrics: time the controller is not engaged (no /ball_reference coming) counts
as error against the last reference, and shows in engaged_frac."""
import numpy as np

from ball_balance.benchmark.live import LiveRecorder, format_metrics
from ball_balance.benchmark.wall_latency import CameraToCommand


def recorder(ref_times):
    rec = LiveRecorder.__new__(LiveRecorder)    # no ROS node: feed the lists directly
    t = np.arange(0.0, 4.0, 0.01)
    rec.truth = [(ti, 0.02, 0.0) for ti in t]   # ball 20 mm off the target throughout
    rec.ref = [(ti, 0.0, 0.0) for ti in ref_times]
    rec.cmd, rec.est, rec.latency, rec.dropped, rec.t0 = [], [], CameraToCommand(), False, 0.0
    rec.pushes = []
    return rec


def test_a_pause_in_the_reference_counts_as_not_engaged_and_as_error():
    steady = np.arange(0.5, 4.0, 0.02)
    gap = steady[(steady < 2.0) | (steady > 3.0)]    # controller went home for 1 s
    full, paused = recorder(steady).metrics(), recorder(gap).metrics()
    assert full["engaged_frac"] == 1.0
    assert 0.6 < paused["engaged_frac"] < 0.75
    assert paused["rmse_m"] == full["rmse_m"] == 0.02


def test_pushes_announced_by_the_simulation_are_timed_from_the_engagement():
    rec = recorder(np.arange(0.5, 4.0, 0.02))   # engaged at 0.5 s on the truth's clock
    t = np.arange(0.0, 4.0, 0.01)
    # 20 mm off until 1.0 s, pushed at 1.0 s (simulated time), back inside 5 mm 0.6 s later
    rec.truth = [(ti, 0.0 if ti < 1.0 or ti >= 1.6 else 0.02, 0.0) for ti in t]
    rec.pushes = [0.2, 1.0]                     # the one before the engagement does not count
    m = rec.metrics()
    assert m["pushes"] == 1 and m["pushes_late"] == 0
    assert abs(m["push_recover_s"] - 0.6) < 0.011
    assert "push recovery mean 0.60 s, worst 0.60 s, 0 of 1 over 1 s" in format_metrics(m)


def test_a_moving_target_is_taken_at_the_truths_instant_not_held():
    # the target moves at 0.1 m/s, published at 60 Hz; the ball sits exactly on it (sampled at
    # 100 Hz): held, the error would be up to 1.7 mm; between two targets it is the path itself
    rec = recorder([])
    speed_m_s = 0.1
    rec.ref = [(ti, speed_m_s * ti, 0.0) for ti in np.arange(0.5, 4.0, 1.0 / 60.0)]
    rec.truth = [(ti, speed_m_s * ti, 0.0) for ti in np.arange(0.0, 3.95, 0.01)]   # none after the last
    assert rec.metrics()["rmse_m"] < 1e-9
    # a pause in the targets is not bridged: the last target is held, as before
    rec.ref = [r for r in rec.ref if not 2.0 < r[0] < 3.0]
    m = rec.metrics()
    assert m["engaged_frac"] < 0.9 and m["rmse_m"] > 0.01


def test_a_push_the_recording_ends_on_is_not_timed():
    rec = recorder(np.arange(0.5, 4.0, 0.02))   # truth until 3.99 s
    rec.pushes = [1.0, 3.0, 4.5]                # 3.0: the run stops 1 s later; 4.5: after the last truth read
    m = rec.metrics()
    assert m["pushes"] == 1
