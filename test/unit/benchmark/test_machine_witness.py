"""The controller manager benchmarks' machine witness: wakeup_baseline.c stopped early still
writes the cycles it ran, and a late cycle of the manager counts as the machine's only when
the witness was late inside that cycle's lateness, the loop's held sleep came back late, or
its lock-releasing sleep came back late with the lock taken straight back."""
import importlib.util
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "test"))     # the benchmark imports the test harness
PATH = ROOT / "benchmarks" / "controller_manager_bench.py"
spec = importlib.util.spec_from_file_location("controller_manager_bench", PATH)
bench = importlib.util.module_from_spec(spec)
spec.loader.exec_module(bench)


def test_a_cycle_is_the_machines_only_when_the_witness_was_late_within_it():
    witness = {"witness_deadline": np.array([1.000, 1.001, 1.002, 1.010]),
               "witness_woke": np.array([1.0001, 1.0045, 1.0021, 1.0102])}   # the second 3.5 ms late
    stalls = bench.witness_stalls(witness)
    assert bench.witness_was_late(stalls, deadline=1.002, start=1.005)           # overlaps the late wake
    assert not bench.witness_was_late(stalls, deadline=1.006, start=1.008)      # after it
    assert not bench.witness_was_late(stalls, deadline=1.0095, start=1.0115)    # only 0.2 ms late there


def test_timing_counts_late_starts_and_those_the_witness_shared():
    period = 0.002
    deadline = np.arange(200) * period + 10.0
    start = deadline + 20e-6
    start[50] += 3e-3       # the machine's: the witness was late then too
    start[120] += 2e-3      # the process's own
    data = {"deadline": deadline, "start": start, "end": start + 1e-4, "woke": start - 1e-4, "ready": start - 5e-5,
            "period": period, "wake_tail": 0.0, "spin_tail": 1e-4,
            "witness_deadline": np.array([deadline[50] + 1e-3]), "witness_woke": np.array([deadline[50] + 2.5e-3])}
    r = bench.timing(data, start[0], start[-1])
    assert (r["late_count"], r["late_shared"]) == (2, 1)
    assert bench.late_starts(r) == "2 (1)"
    del data["witness_deadline"], data["witness_woke"]
    assert bench.late_starts(bench.timing(data, start[0], start[-1])) == "2"


PERIOD, SPIN, HELD = 0.001, 1e-4, 2e-4


def cycles_on_time():
    """300 cycles at 1 kHz whose two sleeps came back on time: deadline, start, woke, ready."""
    deadline = np.arange(300) * PERIOD + 10.0
    woke = deadline - SPIN - HELD + 20e-6            # the lock-releasing sleep
    ready = deadline - SPIN + 10e-6                  # the held sleep
    return deadline, deadline + 5e-6, woke, ready


def cycle_log(deadline, start, woke, ready, **more) -> dict:
    return {"deadline": deadline, "start": start, "end": start + 8e-5, "woke": woke, "ready": ready,
            "period": PERIOD, "wake_tail": HELD, "spin_tail": SPIN, **more}


def test_a_held_sleep_that_came_back_half_a_period_late_is_the_machines_too():
    deadline, start, woke, ready = cycles_on_time()
    ready[100] = deadline[100] + 0.7e-3              # held sleep 0.8 ms late: nothing but the machine holds it up
    start[100] = ready[100] + 3e-6
    woke[200] = deadline[200] + 0.7e-3               # the lock-releasing sleep late: kernel or interpreter lock
    ready[200] = start[200] = woke[200] + 3e-6
    data = cycle_log(deadline, start, woke, ready,
                     witness_deadline=np.array([5.0]), witness_woke=np.array([5.0001]))   # never late
    r = bench.timing(data, start[0], start[-1])
    assert (r["late_count"], r["late_shared"]) == (2, 1)
    del data["witness_deadline"], data["witness_woke"]    # the held sleep tells it without a witness
    assert bench.late_starts(bench.timing(data, start[0], start[-1])) == "2 (1)"


def test_a_late_lock_releasing_sleep_is_the_machines_when_the_lock_was_taken_straight_back():
    deadline, start, woke, ready = cycles_on_time()
    switches = np.ones(300)
    for k, extra_switches in ((100, 0), (200, 2)):     # both sleeps came back 0.7 ms late
        woke[k] = deadline[k] + 0.7e-3
        ready[k] = start[k] = woke[k] + 3e-6
        switches[k] += extra_switches                  # the second then waited for the lock
    data = cycle_log(deadline, start, woke, ready, switches=switches)
    assert bench.late_starts(bench.timing(data, start[0], start[-1])) == "2 (1)"


def test_the_c_wait_stopped_early_writes_the_cycles_it_ran(tmp_path):
    try:
        binary = bench.build_wakeup_baseline()
    except RuntimeError as error:
        pytest.skip(str(error))
    out = tmp_path / "cycles.bin"
    cpu = sorted(os.sched_getaffinity(0))[-1]
    process = subprocess.Popen([str(binary), "1", "1000", "3600", str(cpu), "0", str(out)], stderr=subprocess.PIPE)
    try:
        time.sleep(0.3)
        if process.poll() == 2:
            pytest.skip("SCHED_FIFO refused on this machine")
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=10) == 0
    finally:
        process.kill()
        process.wait()
        shutil.rmtree(binary.parent, ignore_errors=True)
    deadline, start, woke = bench.read_wakeup_log(out)
    assert 50 < len(deadline) < 3_600_000          # the cycles run, not the 3600 s it was given
    assert np.all(np.diff(deadline) > 0) and np.all(start >= deadline) and np.all(woke > 0)
