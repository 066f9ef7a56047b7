"""The loop thread: read -> update -> write at the manager's rate, overruns counted.

Timing: absolute deadlines (next = previous + period) so sleeping jitter does not
accumulate. When a cycle ends after the next deadline the missed periods are counted in
`overruns` / `skipped_periods`, the schedule restarts from now, and one throttled
warning says how many (ros2_control logs every one). With
`expect_blocking_read_write` the hardware's blocking read sets the pace: no sleep, only
`minimum_cycle_time` (s) between cycle starts (0: a tenth of the nominal period, so a read
that does not block after all cannot make a real-time thread spin at full speed). The time given to the cycle is the
manager's clock (`cm.now()`: simulated when a component provides the clock); the period
is the difference of two such times (the nominal period for the first cycle).

Idle work: `idle_hook()` (if set) runs after a cycle only when at least half a period is
left before the next deadline; the node uses it to publish statistics in the loop's
slack, where its interpreter time cannot delay a wake-up (see ros/node.py). The loop
thread asks Linux for 1 us timer slack (default 50 us) so sleeps end on time.
"""
from __future__ import annotations

import ctypes
import os
import threading
import time as _time
from typing import Callable, Optional, Sequence

from .controller_manager import ControllerManager
from .throttle import Throttle


class ControlLoop:
    def __init__(self, cm: ControllerManager, expect_blocking_read_write: bool = False,
                 minimum_cycle_time: float = 0.0, thread_priority: int = 0, cpu_affinity: Sequence[int] = ()):
        """thread_priority: SCHED_FIFO priority of the loop thread (1..99; 0 = leave it normal).
        cpu_affinity: CPUs the loop thread may run on (empty: any)."""
        self.cm = cm
        self.period = 1.0 / cm.update_rate
        self.blocking = expect_blocking_read_write
        self.minimum_cycle_time = minimum_cycle_time
        self.overruns = 0
        self.skipped_periods = 0
        self.cycles = 0
        self.errors = 0  # cycles that raised (a bug): logged throttled, the loop goes on
        self.throttle = Throttle(cm.logger, 5.0)
        self.idle_hook: Optional[Callable[[], None]] = None
        self.thread_priority = thread_priority
        self.cpu_affinity = tuple(cpu_affinity)
        self.realtime = False  # True when the SCHED_FIFO priority was granted
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="controller_manager_loop", daemon=True)

    def start(self) -> None:
        self.cm.loop_running = True
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
        self.cm.loop_running = False

    def _run(self) -> None:
        _set_timer_slack_ns(1000)
        if self.thread_priority > 0:
            self.realtime = set_realtime_priority(self.thread_priority)
            if not self.realtime:
                self.cm.logger.warning(f"could not give the loop thread SCHED_FIFO priority {self.thread_priority} "
                                       "(needs CAP_SYS_NICE or an rtprio limit); running at normal priority, "
                                       "expect more jitter under load")
        if self.cpu_affinity and not set_cpu_affinity(self.cpu_affinity):
            self.cm.logger.warning(f"could not pin the loop thread to CPUs {list(self.cpu_affinity)}; "
                                   "running on any CPU")
        cm, period, stop = self.cm, self.period, self._stop
        monotonic, sleep = _time.monotonic, _time.sleep
        previous = cm.now() - period
        next_deadline = monotonic()
        try:
            while not stop.is_set():
                now = cm.now()
                try:
                    cm.cycle(now, now - previous if now > previous else period)
                except Exception as error:  # noqa: BLE001 - a bug in one cycle does not stop the loop
                    self.errors += 1
                    self.throttle.error("cycle", f"cycle failed: {error!r} (errors so far: {self.errors})")
                previous = now
                self.cycles += 1
                if self.blocking:
                    next_deadline += self.minimum_cycle_time or 0.1 * period
                    delay = next_deadline - monotonic()
                    if delay > 0:
                        sleep(delay)
                    else:
                        next_deadline = monotonic()
                    continue
                next_deadline += period
                delay = next_deadline - monotonic()
                if delay > 0.5 * period and self.idle_hook is not None:
                    try:
                        self.idle_hook()
                    except Exception as error:  # noqa: BLE001 - idle work never stops the loop
                        self.throttle.error("idle", f"idle work failed: {error!r}")
                    delay = next_deadline - monotonic()
                if delay > 0.0:
                    sleep(delay)
                elif -delay >= period:
                    missed = int(-delay / period)
                    self.overruns += 1
                    self.skipped_periods += missed
                    cm.skipped_updates = self.skipped_periods
                    self.throttle.warn("overrun", f"overrun: the cycle took too long, {missed} period(s) of "
                                       f"{period * 1e3:.1f} ms skipped (total {self.skipped_periods})")
                    next_deadline = monotonic()
        finally:
            cm.loop_running = False


def _set_timer_slack_ns(ns: int) -> None:
    """prctl(PR_SET_TIMERSLACK) for the calling thread; silently ignored where unsupported."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(29, ctypes.c_ulong(ns), 0, 0, 0)
    except (OSError, AttributeError):
        pass


def set_cpu_affinity(cpus: Sequence[int]) -> bool:
    """Pin the calling thread to `cpus` (Linux applies affinity per thread); False when refused."""
    try:
        os.sched_setaffinity(0, set(cpus))
        return True
    except (OSError, AttributeError, ValueError):
        return False


def set_realtime_priority(priority: int) -> bool:
    """SCHED_FIFO for the calling thread; False when the system refuses."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        return True
    except (OSError, AttributeError):
        return False
