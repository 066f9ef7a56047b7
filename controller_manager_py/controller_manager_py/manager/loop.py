"""The loop thread: read -> update -> write at the manager's rate, overruns shed, not queued.

Timing: absolute deadlines (next = previous + period) so sleeping jitter does not
accumulate. A cycle that ends after the next deadline is an overrun: the loop does not
run the missed cycles in a burst to catch up; the whole periods missed are counted in
`skipped_periods` (`overruns` counts the late cycles), the schedule restarts from the end
of the late cycle, and one throttled warning says how many. With
`expect_blocking_read_write` the hardware's blocking read sets the pace: no sleep, only
`minimum_cycle_time` (s) between cycle starts (0: a tenth of the nominal period, so a read
that does not block after all cannot make a real-time thread spin at full speed). The time
given to the cycle is the manager's clock (`cm.now()`: simulated when a component provides
the clock); the period is the difference of two such times (the nominal period for the
first cycle).

Where the jitter of a Python loop comes from, and what each knob does about it (figures:
benchmarks/controller_manager_bench.py):
  - The interpreter lock while the loop is awake. Python hands the lock to a thread that
    has waited for it longer than the switch interval, whatever the threads' priorities, and
    a waiting thread's timeout is the interval in force when it began to wait. The executor
    thread, pushed off the lock when the loop wakes, asks for it again at once with the short
    interval: one interval later it takes the lock from the spinning or cycling loop and keeps it
    until it blocks (cycles then start hundreds of microseconds late at 1 kHz although the loop
    wakes on time). With `hold_interpreter` the loop raises the switch interval from its
    wake-up until it sleeps, which delays waits that begin meanwhile but not one already
    begun. What stops it is the executor not running while the loop is awake: the node pins
    the executor thread to the loop thread's CPU at a lower SCHED_FIFO priority
    (`executor_on_loop_cpu`), so the kernel runs it only while the loop sleeps, and a thread
    that does not run cannot ask for the lock.
  - The interpreter lock, at wake-up. After its sleep the loop needs the lock back; if
    another thread holds it (the executor in a callback or a message conversion in C, an
    async controller's worker) the loop waits, as long as that thread's burst of Python or,
    for longer work, the switch interval. Python's wait polls: the waiter sleeps the switch
    interval, asks the holder to drop the lock, and sleeps the interval again until it is
    free. A holder on the loop's own CPU at a lower priority runs only inside those sleeps,
    and in a virtual machine a 20 us sleep costs about as much CPU as it lasts, so the holder
    crawls and the loop waits milliseconds (with the policy controller's worker stepping on
    the loop's CPU) for a lock given up after microseconds of the holder's own time. The
    node's interval is long enough for the holder to run (100 us), and the loop
    takes the lock back before the deadline: the tails below are spent holding it.
  - The kernel's wake-up latency (tens of us, hundreds in a loaded virtual machine).
    `spin_tail` (s): the last part of the wait is a busy loop on the clock (one core busy for
    that long per cycle). `wake_tail` (s): before that, a second sleep *holding* the lock
    (clock_nanosleep through ctypes.PyDLL): a wait for the lock after the first sleep comes
    out of this sleep's time, ahead of the deadline, and this sleep's own late wake-up is
    absorbed by the spin. At most WAKE_TAIL_MAX_FRACTION of a period.
  - Garbage collection. A collection runs in whichever thread allocates, holding the lock;
    a full one over the ~10^5 objects of an rclpy process takes milliseconds. With
    `gc_mode="idle"` the objects alive at start are frozen (gc.freeze), automatic collection
    is off, and the loop collects in its slack (after a cycle with IDLE_GC_FRACTION of a
    period left, or when GC_OVERDUE times late), generation by generation with Python's own
    thresholds; survivors of a full collection are frozen too. "freeze": frozen at start, collection automatic.
    "automatic": Python's default. When the loop stops, automatic collection is restored.
  - Scheduling: the loop thread's SCHED_FIFO priority and CPU affinity (realtime.py).

Idle work: after each cycle `idle_hook(budget)` (if set) is called with the time (s) left
before the loop must start waiting for its next deadline (0 after a cycle that overran);
it must do only what fits, and what is overdue
(the node publishes statistics there when its measured cost fits the budget, else a cycle
later, but never more than a publishing period late: see ros/node.py). Garbage is collected
(gc_mode "idle") when more than IDLE_GC_FRACTION of a period is left, or once overdue.

Cycle log: with `cycle_log` set (a path), the last CYCLE_LOG_LENGTH cycles' deadline,
start and end, and when the wait before it came back from its lock-releasing sleep
(`woke`, the lock re-acquired) and from its lock-holding sleep (`ready`), all
time.monotonic() s, and the loop thread's voluntary context switches during the
lock-releasing sleep (`switches`: 1 when it slept and took the lock straight back, more when
it then had to wait for the lock, so a late `woke` with 1 is the kernel's or the machine's),
are kept in preallocated arrays and written to that .npz file when the loop stops (with
`wake_tail` and `spin_tail`), for timing analysis: the benchmark reads it.
"""
from __future__ import annotations

import gc
import resource
import sys
import threading
import time as _time
from array import array
from typing import Callable, Optional, Sequence

from ..realtime import configure_thread, sleep_until
from .controller_manager import ControllerManager
from .throttle import Throttle

GC_MODES = ("idle", "freeze", "automatic")
CYCLE_LOG_LENGTH = 1 << 16
MIN_PERIOD_FRACTION = 0.98
"""After a late start the next cycle comes at least this fraction of a period later: a late
wake-up moves the schedule instead of being followed by a short period."""
WAKE_TAIL_MAX_FRACTION = 0.2
"""The held sleep takes at most this share of a period: the executor gets the interpreter only
outside the cycle and the tails, and at 1 kHz a 300 us held sleep (with the 100 us spin) leaves
it too little: it falls behind and holds the lock at the loop's wake-ups, and many more cycles
start late than with 200 us."""
IDLE_GC_FRACTION = 0.3
GC_OVERDUE = 50  # times the first generation's threshold: collected even without slack
setswitchinterval = sys.setswitchinterval
thread_usage = resource.getrusage   # (cycle log only: about 1 us a call)
RUSAGE_THREAD = getattr(resource, "RUSAGE_THREAD", resource.RUSAGE_SELF)   # (Linux has it)


class ControlLoop:
    def __init__(self, cm: ControllerManager, expect_blocking_read_write: bool = False,
                 minimum_cycle_time: float = 0.0, thread_priority: int = 0, cpu_affinity: Sequence[int] = (),
                 wake_tail: float = 0.0, spin_tail: float = 0.0, gc_mode: str = "automatic",
                 hold_interpreter: bool = False, cycle_log: str = ""):
        """thread_priority: SCHED_FIFO priority of the loop thread (1..99; 0 = leave it normal).
        cpu_affinity: CPUs the loop thread may run on (empty: any). wake_tail, spin_tail (s),
        gc_mode, hold_interpreter, cycle_log: see the module docstring."""
        if gc_mode not in GC_MODES:
            raise ValueError(f"gc_mode must be one of {GC_MODES}, got {gc_mode!r}")
        self.cm = cm
        self.period = 1.0 / cm.update_rate
        self.blocking = expect_blocking_read_write
        self.minimum_cycle_time = minimum_cycle_time
        self.wake_tail = min(max(0.0, wake_tail), WAKE_TAIL_MAX_FRACTION * self.period)
        self.spin_tail = min(max(0.0, spin_tail), 0.5 * self.period)
        self.gc_mode = gc_mode
        self.hold_interpreter = hold_interpreter
        self.overruns = 0  # cycles that ended after the next deadline
        self.skipped_periods = 0  # whole periods with no cycle because of overruns
        self.cycles = 0
        self.collections = 0  # garbage collections run in the loop's slack (gc_mode "idle")
        self.errors = 0  # cycles that raised (a bug): logged throttled, the loop goes on
        self.throttle = Throttle(cm.logger, 5.0)
        self.idle_hook: Optional[Callable[[float], None]] = None  # idle_hook(budget s): see the docstring
        self.thread_priority = thread_priority
        self.cpu_affinity = tuple(cpu_affinity)
        self.realtime = False  # True when the SCHED_FIFO priority was granted
        self.cycle_log = cycle_log
        # deadline, start, end, woke, ready, switches (see the module docstring)
        self._log = tuple(array("d", bytes(8 * CYCLE_LOG_LENGTH)) for _ in range(6)) if cycle_log else None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="controller_manager_loop", daemon=True)

    def start(self) -> None:
        self.cm.loop_running = True
        self._thread.start()

    def stop(self) -> None:
        """Stop the loop (returns within about a period); idempotent, any thread."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        self.cm.loop_running = False

    def _run(self) -> None:
        self.realtime = configure_thread(self.cm.logger, "the loop thread", self.thread_priority,
                                         self.cpu_affinity, timer_slack_ns=1000)
        if self.gc_mode != "automatic":
            gc.collect()
            gc.freeze()  # what exists now lives as long as the process: never scanned again
            if self.gc_mode == "idle":
                gc.disable()
        switch_interval = sys.getswitchinterval()
        try:
            self._cycles()
        finally:
            setswitchinterval(switch_interval)  # (raised while the loop held the lock)
            if self.gc_mode == "idle":
                gc.enable()
            self.cm.loop_running = False
            self._write_cycle_log()

    def _cycles(self) -> None:
        cm, period, stop = self.cm, self.period, self._stop
        tail, spin = self.wake_tail + self.spin_tail, self.spin_tail
        monotonic, sleep = _time.monotonic, _time.sleep
        log = self._log
        hold = self.hold_interpreter
        wake_interval = sys.getswitchinterval()  # how soon the loop asks for the lock when it wakes
        hold_interval = max(wake_interval, period)  # how long others wait before asking it back
        min_gap = MIN_PERIOD_FRACTION * period
        previous = cm.now() - period
        next_deadline = monotonic()
        while not stop.is_set() and not cm.stopping:
            if hold:
                setswitchinterval(hold_interval)
            start = monotonic()
            now = cm.now()
            try:
                cm.cycle(now, now - previous if now > previous else period)
            except Exception as error:  # noqa: BLE001 - a bug in one cycle does not stop the loop
                self.errors += 1
                self.throttle.error("cycle", f"cycle failed: {error!r} (errors so far: {self.errors})")
            previous = now
            if log is not None:
                i = self.cycles % CYCLE_LOG_LENGTH
                log[0][i], log[1][i], log[2][i] = next_deadline, start, monotonic()
            self.cycles += 1
            if self.blocking:
                next_deadline += self.minimum_cycle_time or 0.1 * period
                self._idle_work(next_deadline)
                delay = next_deadline - monotonic()
                if hold:
                    setswitchinterval(wake_interval)
                if delay > 0:
                    sleep(delay)
                else:
                    next_deadline = monotonic()
                continue
            # the next deadline on the grid, but never so soon after a late start that the
            # period would shrink by more than MIN_PERIOD_FRACTION (the grid moves instead)
            next_deadline += period
            if next_deadline < start + min_gap:
                next_deadline = start + min_gap
            delay = next_deadline - monotonic()
            if delay <= 0.0:
                self._overrun(-delay)
                next_deadline = monotonic()
                self._idle_work(next_deadline)  # no slack: only what is overdue
                continue
            self._idle_work(next_deadline - tail)
            delay = next_deadline - monotonic()
            if hold:
                setswitchinterval(wake_interval)
            if log is not None:
                switches = thread_usage(RUSAGE_THREAD).ru_nvcsw
            if delay > tail:
                sleep(delay - tail)  # releases the interpreter lock
            if hold:
                setswitchinterval(hold_interval)
            if log is not None:
                i = self.cycles % CYCLE_LOG_LENGTH
                log[3][i] = monotonic()
                log[5][i] = thread_usage(RUSAGE_THREAD).ru_nvcsw - switches
            if tail > spin:
                sleep_until(next_deadline - spin, hold_interpreter=True)
            if log is not None:
                log[4][i] = monotonic()
            if spin > 0.0:
                while monotonic() < next_deadline:
                    pass

    def _idle_work(self, until: float) -> None:
        """Between cycles, until `until` (time.monotonic() s; now or past after a cycle that
        left no slack): garbage (gc_mode "idle") when more than IDLE_GC_FRACTION of a period is
        left, or once overdue (GC_OVERDUE: a loop with no slack must not grow without bound);
        then the idle hook with the time left (0 if none), which does what fits in it and what
        is overdue. A machine too slow for the loop's rate still collects and reports."""
        if self.gc_mode == "idle" and (until - _time.monotonic() > IDLE_GC_FRACTION * self.period
                                       or gc.get_count()[0] > GC_OVERDUE * gc.get_threshold()[0]):
            self._collect_garbage()
        if self.idle_hook is not None:
            try:
                self.idle_hook(max(0.0, until - _time.monotonic()))
            except Exception as error:  # noqa: BLE001 - idle work never stops the loop
                if self.cm.stop_if_shut_down():
                    return
                self.throttle.error("idle", f"idle work failed: {error!r}")

    def _overrun(self, late: float) -> None:
        """The cycle ended `late` s after the next deadline: shed, count, warn (throttled)."""
        missed = int(late / self.period)
        self.overruns += 1
        self.skipped_periods += missed
        self.cm.skipped_updates = self.skipped_periods
        self.cm.overruns = self.overruns
        self.throttle.warn("overrun", f"overrun: a cycle ended {late * 1e3:.2f} ms after the next deadline "
                           f"({self.period * 1e3:.2f} ms period); {missed} period(s) skipped, not caught up "
                           f"(overruns so far: {self.overruns}, skipped periods: {self.skipped_periods})")

    def _collect_garbage(self) -> None:
        """In the loop's slack: the collection Python would have run automatically, if due."""
        count0, count1, count2 = gc.get_count()
        threshold0, threshold1, threshold2 = gc.get_threshold()
        if count0 < threshold0:
            return
        generation = 0
        if count1 >= threshold1:
            generation = 2 if count2 >= threshold2 else 1
        gc.collect(generation)
        if generation == 2:
            gc.freeze()
        self.collections += 1

    def _write_cycle_log(self) -> None:
        if self._log is None:
            return
        try:
            import numpy as np

            n = min(self.cycles, CYCLE_LOG_LENGTH)
            order = [(self.cycles - n + k) % CYCLE_LOG_LENGTH for k in range(n)]
            deadline, start, end, woke, ready, switches = (np.frombuffer(a, dtype=np.float64)[order]
                                                           for a in self._log)
            np.savez(self.cycle_log, deadline=deadline, start=start, end=end, woke=woke, ready=ready,
                     switches=switches, period=self.period, wake_tail=self.wake_tail, spin_tail=self.spin_tail)
        except Exception as error:  # noqa: BLE001 - a diagnostic aid never breaks shutdown
            self.cm.logger.error(f"cannot write the cycle log {self.cycle_log}: {error!r}")
