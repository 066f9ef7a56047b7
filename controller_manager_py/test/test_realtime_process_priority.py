"""realtime.set_process_realtime_priority: every thread of a process, those Python did not
start included, and the threads started afterwards (they inherit it)."""
import json
import os
import subprocess
import sys
import textwrap

import pytest

from controller_manager_py import realtime

CHILD = textwrap.dedent("""
    import ctypes, json, os, sys, threading, time
    from controller_manager_py import realtime

    # a thread Python knows nothing about, as a DDS library starts them (pthread via libc)
    libc = ctypes.CDLL(None)
    thread_fn = ctypes.CFUNCTYPE(ctypes.c_void_p, ctypes.c_void_p)(lambda _: libc.sleep(30))
    handle = ctypes.c_ulong()
    libc.pthread_create(ctypes.byref(handle), None, thread_fn, None)
    before = threading.Event()
    threading.Thread(target=before.wait, daemon=True).start()
    time.sleep(0.1)
    granted = realtime.set_process_realtime_priority(1)
    later = threading.Event()
    threading.Thread(target=later.wait, daemon=True).start()
    policies = {tid: os.sched_getscheduler(tid) for tid in realtime.process_thread_ids()}
    print(json.dumps({"granted": granted, "policies": list(policies.values())}), flush=True)
    os._exit(0)
""")


def test_process_priority_reaches_every_thread_and_the_ones_started_later():
    out = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=60,
                         env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    result = json.loads(out.stdout.strip().splitlines()[-1])
    if not result["granted"]:
        pytest.skip("SCHED_FIFO refused here (no CAP_SYS_NICE or rtprio limit)")
    assert len(result["policies"]) >= 4          # main, the C thread, two Python threads
    assert set(result["policies"]) == {os.SCHED_FIFO}


def test_process_priority_says_when_refused_instead_of_raising():
    assert realtime.set_process_realtime_priority(1000) is False     # no such priority
    assert realtime.set_realtime_priority(1000, thread_id=realtime.process_thread_ids()[0]) is False
    assert os.getpid() in realtime.process_thread_ids()
