"""The loop thread's timing behaviour: overruns shed (never a burst), garbage collected in the
loop's slack, the interpreter lock held through a cycle, the cycle log, realtime helpers.

Timing is only asserted where the loop guarantees it by construction (a gap between cycle
starts is never shorter than the minimum period fraction, whatever the machine's load)."""
import gc
import sys
import threading
import time

import numpy as np
import pytest
from cm_helpers import make_manager, spawn

from controller_manager_py import realtime
from controller_manager_py.hardware_interface import return_type
from controller_manager_py.manager.loop import MIN_PERIOD_FRACTION, WAKE_TAIL_MAX_FRACTION, ControlLoop

COUNTING = "cm_helpers:CountingController"


def wait_for(condition, timeout=10.0):
    deadline = time.monotonic() + timeout
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.005)
    return condition()


def run_loop(loop, until):
    loop.start()
    try:
        assert wait_for(until)
    finally:
        loop.stop()


def test_an_overrun_is_shed_and_counted_never_caught_up_in_a_burst(tmp_path):
    cm = make_manager(rate=200)
    counting = spawn(cm, "c", COUNTING)
    log = tmp_path / "cycles.npz"
    loop = ControlLoop(cm, cycle_log=str(log))
    counting.sleep_s = 0.03  # six periods long
    counting.release.clear()
    run_loop(loop, lambda: counting.calls >= 3)
    counting.sleep_s = 0.0
    assert loop.overruns >= 1 and loop.skipped_periods >= 5
    assert cm.skipped_updates == loop.skipped_periods and cm.overruns == loop.overruns
    starts = np.load(log)["start"]
    assert len(starts) == loop.cycles
    assert np.diff(starts).min() >= MIN_PERIOD_FRACTION * loop.period - 1e-6


def test_short_periods_never_follow_a_late_start(tmp_path):
    cm = make_manager(rate=500)
    log = tmp_path / "cycles.npz"
    loop = ControlLoop(cm, cycle_log=str(log), wake_tail=1e-4, spin_tail=5e-5, hold_interpreter=True)
    run_loop(loop, lambda: loop.cycles >= 200)
    data = np.load(log)
    assert float(data["period"]) == pytest.approx(0.002)
    assert np.diff(data["start"]).min() >= MIN_PERIOD_FRACTION * 0.002 - 1e-6
    assert (data["end"] >= data["start"]).all()


def test_the_cycle_log_counts_the_waits_for_the_interpreter_lock_after_the_sleep(tmp_path):
    """One voluntary context switch for the sleep alone; more while another thread keeps the
    lock (here a busy Python thread with a short switch interval)."""
    import sys
    import threading

    def switches(busy: bool):
        log = tmp_path / f"cycles_{busy}.npz"
        loop = ControlLoop(make_manager(rate=500), cycle_log=str(log))
        stop = threading.Event()

        def hold_the_lock():
            while not stop.is_set():
                pass

        holder = threading.Thread(target=hold_the_lock, daemon=True)
        if busy:
            holder.start()
        try:
            run_loop(loop, lambda: loop.cycles >= 100)
        finally:
            stop.set()
        return np.load(log)["switches"][10:]    # (the first cycles: start-up)

    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-4)
    try:
        assert np.median(switches(busy=False)) == 1
        assert np.median(switches(busy=True)) >= 2
    finally:
        sys.setswitchinterval(interval)


def test_the_held_sleep_is_capped_at_a_share_of_the_period():
    assert ControlLoop(make_manager(rate=500), wake_tail=3e-4).wake_tail == pytest.approx(3e-4)
    at_1_khz = ControlLoop(make_manager(rate=1000), wake_tail=3e-4)
    assert at_1_khz.wake_tail == pytest.approx(WAKE_TAIL_MAX_FRACTION * 1e-3)
    assert ControlLoop(make_manager(rate=500), wake_tail=-1.0).wake_tail == 0.0


class Littering:
    """A controller that leaves reference cycles behind (garbage only the collector frees)."""

    def __init__(self):
        self.calls = 0

    def __call__(self):
        for _ in range(20):
            junk = []
            junk.append(junk)
        self.calls += 1


def test_gc_idle_mode_collects_in_the_loop_slack_and_restores_automatic_collection():
    assert gc.isenabled()
    cm = make_manager(rate=200)
    counting = spawn(cm, "c", COUNTING)
    litter = Littering()
    original = counting.update

    def update(time_, period):
        litter()
        return original(time_, period)
    counting.update = update
    loop = ControlLoop(cm, gc_mode="idle")
    disabled = []
    loop.start()
    try:
        assert wait_for(lambda: loop.collections >= 1)
        disabled.append(gc.isenabled())
    finally:
        loop.stop()
        gc.unfreeze()
    assert disabled == [False] and gc.isenabled()


def test_a_loop_that_keeps_overrunning_still_does_its_idle_work():
    # every cycle longer than the period (a machine too slow for the rate): the idle hook still
    # runs after each one, with no budget (the node publishes only what is overdue), and the
    # garbage of gc_mode "idle" is still collected once overdue
    cm = make_manager(rate=200)
    counting = spawn(cm, "c", COUNTING)
    litter = Littering()
    original = counting.update

    def update(time_, period):
        for _ in range(10):
            litter()
        return original(time_, period)
    counting.update = update
    counting.sleep_s = 0.008   # the period is 5 ms
    counting.release.clear()
    loop = ControlLoop(cm, gc_mode="idle")
    budgets = []
    loop.idle_hook = budgets.append
    gc.collect()
    loop.start()
    try:
        assert wait_for(lambda: loop.collections >= 1 and loop.cycles >= 30, timeout=60.0)
    finally:
        loop.stop()
        gc.unfreeze()
    assert loop.overruns >= loop.cycles - 2
    assert len(budgets) >= loop.cycles - 1 and budgets.count(0.0) >= loop.cycles - 3


def test_idle_work_failing_after_the_context_ends_stops_the_loop_quietly():
    # Ctrl-C shuts the ROS context down under the running loop: the idle hook's next publish
    # fails, which is the end of the process, not a fault to log
    cm = make_manager(rate=200)
    alive = [True]
    cm.alive = lambda: alive[0]
    errors = []
    loop = ControlLoop(cm)
    loop.throttle.error = lambda key, text: errors.append(text)

    def publish(budget):
        if not alive[0]:
            raise RuntimeError("publisher's context is invalid")
    loop.idle_hook = publish
    loop.start()
    try:
        assert wait_for(lambda: loop.cycles >= 5)
        alive[0] = False
        assert wait_for(lambda: cm.stopping)
    finally:
        loop.stop()
    assert errors == []


def test_unknown_gc_mode_is_refused():
    with pytest.raises(ValueError, match="gc_mode must be one of"):
        ControlLoop(make_manager(), gc_mode="sometimes")


def test_holding_the_interpreter_raises_the_switch_interval_in_cycles_and_gives_it_back():
    before = sys.getswitchinterval()
    cm = make_manager(rate=100)
    seen = []
    counting = spawn(cm, "c", COUNTING)
    original = counting.update

    def update(time_, period):
        seen.append(sys.getswitchinterval())
        return original(time_, period)
    counting.update = update
    loop = ControlLoop(cm, hold_interpreter=True)
    run_loop(loop, lambda: len(seen) >= 3)
    assert min(seen) >= loop.period  # raised during the cycle
    assert sys.getswitchinterval() == before  # and given back when the loop stopped


def test_stop_is_idempotent_and_callable_from_any_thread():
    cm = make_manager(rate=200)
    loop = ControlLoop(cm)
    loop.start()
    assert wait_for(lambda: loop.cycles > 2)
    stopper = threading.Thread(target=loop.stop)
    stopper.start()
    stopper.join(10)
    loop.stop()
    assert not cm.loop_running


def test_a_loop_ends_quietly_when_the_process_is_stopping():
    cm = make_manager(rate=200)
    counting = spawn(cm, "c", COUNTING)
    alive = [True]
    cm.alive = lambda: alive[0]
    loop = ControlLoop(cm)
    loop.start()
    try:
        assert wait_for(lambda: counting.calls > 2)
        alive[0] = False
        counting.raise_error = True  # as a publish on a shut-down context
        assert wait_for(lambda: not loop._thread.is_alive())
    finally:
        loop.stop()
    assert cm.stopping and cm.controllers["c"].update_errors == 0


def test_sleep_until_returns_at_or_after_the_deadline_with_or_without_the_lock():
    for hold in (False, True):
        deadline = time.monotonic() + 0.002
        realtime.sleep_until(deadline, hold_interpreter=hold)
        assert time.monotonic() >= deadline


def test_realtime_helpers_say_when_refused_instead_of_raising():
    assert realtime.set_cpu_affinity([10_000]) is False
    assert realtime.set_realtime_priority(1000) is False
    assert isinstance(realtime.has_realtime_kernel(), bool)
    assert realtime.set_timer_slack_ns(50_000) in (True, False)
    assert return_type.OK == 0
