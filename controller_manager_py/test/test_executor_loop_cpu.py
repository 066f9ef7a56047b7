"""executor_on_loop_cpu: which CPU the loop and the executor share, and threads started from
a pinned executor thread (an async controller's) still run on any CPU unless told otherwise."""
import os
import threading
import time

from controller_manager_py.hardware_interface.types import return_type
from controller_manager_py.manager.async_handler import PROCESS_CPUS, AsyncHandler
from controller_manager_py.realtime import set_cpu_affinity
from controller_manager_py.ros.node import shared_loop_cpu


def test_shared_cpu_is_the_first_configured_or_the_last_allowed():
    assert shared_loop_cpu([3, 1]) == 3
    assert shared_loop_cpu([]) == max(os.sched_getaffinity(0))


def test_async_thread_started_from_a_pinned_thread_runs_on_any_cpu():
    seen = {}

    def start_from_pinned_thread():
        set_cpu_affinity([PROCESS_CPUS[-1]])
        handler = AsyncHandler("unpinned", lambda time, period: return_type.OK)
        deadline = time.monotonic() + 10  # (the worker applies its affinity first thing)
        while time.monotonic() < deadline:
            seen["cpus"] = os.sched_getaffinity(handler._thread.native_id)
            if seen["cpus"] == set(PROCESS_CPUS):
                break
            time.sleep(0.01)
        handler.stop()

    thread = threading.Thread(target=start_from_pinned_thread)
    thread.start()
    thread.join(10)
    assert seen["cpus"] == set(PROCESS_CPUS)


def test_async_thread_on_trigger_cpus_follows_the_first_triggering_thread():
    """on_trigger_cpus: the worker moves to the CPUs of the (loop) thread that triggers it."""
    seen = {}
    handler = AsyncHandler("on loop cpu", lambda time, period: seen.setdefault(
        "cpus", os.sched_getaffinity(0)) and return_type.OK, on_trigger_cpus=True)

    def trigger_from_pinned_thread():
        set_cpu_affinity([PROCESS_CPUS[-1]])
        handler.trigger(0.0, 0.002)
        handler.wait_idle(10.0)

    thread = threading.Thread(target=trigger_from_pinned_thread)
    thread.start()
    thread.join(15)
    handler.stop()
    assert seen["cpus"] == {PROCESS_CPUS[-1]}
