"""Run a callable in a worker thread with ros2_control's AsyncFunctionHandler semantics.

`trigger(time, period)` hands the arguments to the worker and returns immediately; when
the previous call is still running the trigger is skipped (counted in `skipped`) and the
last result is returned again. In "detached" mode the worker runs on its own at `rate_hz`
and trigger() only reports the last result. Used for is_async controllers and hardware.

`on_trigger_cpus`: the worker moves to the CPUs of the thread that first triggers it (the
manager's loop thread, which the node pins to one CPU with `executor_on_loop_cpu`). With a
SCHED_FIFO priority below the loop's, the worker then runs only while the loop sleeps, as the
executor thread does: it cannot ask for Python's interpreter lock while the loop holds it.
On another CPU it can, and does (a 2 ms step of Python is a long run of bytecode): the loop,
made to give the lock back a switch interval after taking it, then waits for it for as long as its own
raised switch interval (hold_interpreter, a period), and that cycle starts late.
"""
from __future__ import annotations

import os
import threading
import time as _time
from typing import Callable, Sequence

from ..hardware_interface.types import return_type
from ..realtime import configure_thread

try:  # the CPUs the process may use, read before any thread is pinned (for "any CPU")
    PROCESS_CPUS = tuple(sorted(os.sched_getaffinity(0)))
except (AttributeError, OSError):
    PROCESS_CPUS = ()


class AsyncHandler:
    def __init__(self, name: str, function: Callable[[float, float], return_type],
                 detached: bool = False, rate_hz: float = 0.0, clock: Callable[[], float] = _time.monotonic,
                 thread_priority: int = 0, affinity: Sequence[int] = (), on_trigger_cpus: bool = False):
        self.name = name
        self._function = function
        self._detached = detached
        self._period = 1.0 / rate_hz if rate_hz > 0 else 0.0
        self._clock = clock
        self._wake = threading.Event()
        self._stop = False
        self._busy = False
        self._args = (0.0, 0.0)
        self.last_result = return_type.OK
        self.skipped = 0
        self.runs = 0
        self.last_exception: BaseException | None = None
        self.last_finish = float("nan")  # clock time of the last completed run (data age)
        self.last_duration = 0.0
        self.thread_priority = thread_priority  # SCHED_FIFO when > 0 and permitted
        self.affinity = tuple(affinity)  # CPUs for the thread (empty: any)
        self._pin_to_trigger = on_trigger_cpus and not detached
        self._pin_cpus: tuple = ()  # the first triggering thread's CPUs, applied by the worker once
        self._thread = threading.Thread(target=self._run, name=f"async:{name}", daemon=True)
        self._thread.start()

    def trigger(self, time: float, period: float) -> return_type:
        if self._detached:
            return self.last_result
        if self._busy:
            self.skipped += 1
            return self.last_result
        self._args = (time, period)
        if self._pin_to_trigger:
            self._pin_to_trigger = False
            try:
                self._pin_cpus = tuple(os.sched_getaffinity(0))   # (0: the calling thread)
            except (AttributeError, OSError):
                pass
        self._busy = True
        self._wake.set()
        return self.last_result

    @property
    def busy(self) -> bool:
        return self._busy

    def wait_idle(self, timeout: float = 1.0) -> bool:
        deadline = _time.monotonic() + timeout
        while self._busy and _time.monotonic() < deadline:
            _time.sleep(0.0005)
        return not self._busy

    def stop(self) -> None:
        self._stop = True
        self._wake.set()
        self._thread.join(timeout=2.0)

    def _call(self, time: float, period: float) -> None:
        start = _time.monotonic()
        try:
            self.last_result = self._function(time, period)
        except Exception as error:  # noqa: BLE001 - reported to the loop as ERROR
            self.last_exception = error
            self.last_result = return_type.ERROR
        self.runs += 1
        self.last_finish = self._clock()
        self.last_duration = _time.monotonic() - start

    def _run(self) -> None:
        # empty affinity is any CPU, not the starting thread's: the executor thread, which
        # activates controllers, may be pinned to the loop's CPU (executor_on_loop_cpu)
        configure_thread(None, f"async thread '{self.name}'", self.thread_priority, self.affinity or PROCESS_CPUS)
        if self._detached:
            period = self._period or 0.01
            next_time = _time.monotonic()
            last = self._clock()
            while not self._stop:
                now = self._clock()
                self._call(now, now - last)
                last = now
                next_time += period
                delay = next_time - _time.monotonic()
                if delay > 0:
                    _time.sleep(delay)
                else:
                    next_time = _time.monotonic()
            return
        while True:
            self._wake.wait()
            self._wake.clear()
            if self._stop:
                return
            if self._pin_cpus:
                cpus, self._pin_cpus = self._pin_cpus, ()
                configure_thread(None, f"async thread '{self.name}'", 0, cpus)
            self._call(*self._args)
            self._busy = False
