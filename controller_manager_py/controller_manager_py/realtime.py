"""Real-time helpers for the calling thread (the room of ros2_control's realtime_tools).

Used by the manager's loop thread, async controllers and hardware, and any node that runs
a thread with a deadline. Linux applies scheduling policy, CPU affinity and timer slack
per thread, so each helper changes the thread that calls it. None of them raises: each
returns False (or a reason) when the system refuses, and the caller decides how loudly
to say so (`configure_thread` logs one warning line).

realtime_tools equivalents: `configure_sched_fifo` (ours: `set_realtime_priority`),
`set_current_thread_affinity` (ours: `set_cpu_affinity`, taking a set of CPUs),
`lock_memory`, `has_realtime_kernel`.
"""
from __future__ import annotations

import ctypes
import os
import threading
from pathlib import Path
from typing import Optional, Sequence

_PR_SET_TIMERSLACK = 29
_MCL_CURRENT, _MCL_FUTURE = 1, 2
_CLOCK_MONOTONIC, _TIMER_ABSTIME = 1, 1


def _libc():
    return ctypes.CDLL(None, use_errno=True)


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


# ctypes.CDLL releases the interpreter lock around a call, ctypes.PyDLL keeps it
_nanosleep_releasing = _libc().clock_nanosleep
_nanosleep_holding = ctypes.PyDLL(None).clock_nanosleep
for _f in (_nanosleep_releasing, _nanosleep_holding):
    _f.argtypes = (ctypes.c_int, ctypes.c_int, ctypes.POINTER(_Timespec), ctypes.c_void_p)
    _f.restype = ctypes.c_int


def sleep_until(deadline: float, hold_interpreter: bool = False) -> None:
    """Sleep until `deadline` on the time.monotonic() clock (CLOCK_MONOTONIC, absolute, so
    the time spent computing the delay does not add up). hold_interpreter=True keeps
    Python's interpreter lock while sleeping: no other Python thread runs meanwhile, and the
    caller continues at the deadline without waiting for the lock (use for short tails only)."""
    ns = int(deadline * 1e9)
    ts = _Timespec(ns // 1_000_000_000, ns % 1_000_000_000)
    call = _nanosleep_holding if hold_interpreter else _nanosleep_releasing
    while call(_CLOCK_MONOTONIC, _TIMER_ABSTIME, ctypes.byref(ts), None) == 4:  # EINTR: a signal
        pass


def set_realtime_priority(priority: int, thread_id: int = 0) -> bool:
    """SCHED_FIFO at `priority` (1..99) for the calling thread (or the thread `thread_id` of
    this process, a native id as in threading.get_native_id()); False when refused (needs
    CAP_SYS_NICE or an `rtprio` limit, see `ulimit -r`)."""
    try:
        os.sched_setscheduler(thread_id, os.SCHED_FIFO, os.sched_param(priority))
        return True
    except (OSError, AttributeError, ValueError):
        return False


def process_thread_ids() -> list:
    """Native ids of every thread of this process now (/proc/self/task), including threads
    that Python did not start (a DDS library's receive threads)."""
    try:
        return sorted(int(tid) for tid in os.listdir("/proc/self/task"))
    except OSError:
        return [threading.get_native_id()]


def set_process_realtime_priority(priority: int) -> bool:
    """SCHED_FIFO at `priority` for every thread of this process that exists now; threads
    started later inherit the policy of the thread that starts them. For a process whose
    whole work is one short real-time chain (receive, compute, send): its middleware's
    receive threads wake it, so they need the priority as much as its own threads. False
    when refused for any thread."""
    granted = True
    for thread_id in process_thread_ids():
        try:
            os.sched_setscheduler(thread_id, os.SCHED_FIFO, os.sched_param(priority))
        except ProcessLookupError:      # the thread ended meanwhile
            pass
        except (OSError, AttributeError, ValueError):
            granted = False
    return granted


def set_cpu_affinity(cpus: Sequence[int]) -> bool:
    """Pin the calling thread to `cpus`; False when refused or a CPU does not exist."""
    try:
        os.sched_setaffinity(0, set(cpus))
        return True
    except (OSError, AttributeError, ValueError):
        return False


def set_timer_slack_ns(ns: int) -> bool:
    """prctl(PR_SET_TIMERSLACK) for the calling thread: how late the kernel may end its
    sleeps to batch wake-ups (default 50 us; SCHED_FIFO threads get none anyway)."""
    try:
        return _libc().prctl(_PR_SET_TIMERSLACK, ctypes.c_ulong(ns), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def lock_memory() -> Optional[str]:
    """mlockall(current and future pages) for the process, so no page fault delays a
    cycle; None on success, else the reason (usually RLIMIT_MEMLOCK)."""
    try:
        libc = _libc()
        if libc.mlockall(_MCL_CURRENT | _MCL_FUTURE) == 0:
            return None
        return os.strerror(ctypes.get_errno())
    except (OSError, AttributeError) as error:
        return str(error)


# glibc mallopt() parameters
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD_MAX_BYTES = 32 * 1024 * 1024     # glibc's ceiling for M_MMAP_THRESHOLD (64-bit)


def reuse_freed_memory(largest_block_bytes: int = MMAP_THRESHOLD_MAX_BYTES,
                       keep_free_bytes: int = 2 * MMAP_THRESHOLD_MAX_BYTES) -> bool:
    """Let glibc's malloc serve blocks up to `largest_block_bytes` from the heap and keep up to
    `keep_free_bytes` of freed heap instead of returning it to the kernel. For a process that
    allocates and frees a large buffer per message (a camera frame: 0.9 MB at 640x480): by
    default each such block is mapped fresh and unmapped when freed, so every frame pays
    a page fault per 4 KiB page (about 1 ms per 640x480 frame measured on a 2-core VM); from
    the heap it reuses pages already mapped. False when the C library has no mallopt (not
    glibc) or refuses."""
    try:
        mallopt = _libc().mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, min(largest_block_bytes, MMAP_THRESHOLD_MAX_BYTES))
                and mallopt(_M_TRIM_THRESHOLD, keep_free_bytes))


def has_realtime_kernel() -> bool:
    """True on a PREEMPT_RT kernel (/sys/kernel/realtime reads 1)."""
    try:
        return Path("/sys/kernel/realtime").read_text().strip() == "1"
    except OSError:
        return False


def configure_thread(logger, what: str, priority: int = 0, cpus: Sequence[int] = (),
                     timer_slack_ns: Optional[int] = None) -> bool:
    """Apply priority (0: leave normal), affinity (empty: any CPU) and timer slack to the
    calling thread; one warning line per refusal naming `what`. True when the SCHED_FIFO
    priority was granted."""
    if timer_slack_ns is not None:
        set_timer_slack_ns(timer_slack_ns)
    realtime = False
    if priority > 0:
        realtime = set_realtime_priority(priority)
        if not realtime and logger is not None:
            logger.warning(f"could not give {what} SCHED_FIFO priority {priority} (needs CAP_SYS_NICE or an "
                           "rtprio limit); running at normal priority, expect more jitter under load")
    if cpus and not set_cpu_affinity(cpus) and logger is not None:
        logger.warning(f"could not pin {what} to CPUs {list(cpus)}; running on any CPU")
    return realtime
