"""Shared fixtures. Integration tests get a private ROS domain, a process launcher that
always cleans up, and an in-test graph node; see harness.py."""
import faulthandler
import os
import signal
import sys
import threading

import pytest

from harness import DomainLease, Graph, Launcher

if not os.environ.get("BALL_BALANCE_ROOT"):
    raise pytest.UsageError("run the tests through scripts/test.sh (or `source env.sh` first)")

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_LOCALHOST_ONLY", None)

# The tests stop nodes and scripts with SIGINT, as Ctrl-C in a terminal does. A test run started
# as a background job of a script (`scripts/test.sh &`, a CI runner) inherits SIGINT ignored, and
# every process it starts would then ignore it too (bash cannot even trap it). A handler here is
# reset to the default in each started process.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


# pytest-timeout (300 s, or a test's own mark) interrupts a test with a signal, which takes
# effect only when the main thread is back in Python, and its timer is spent once it has fired:
# a teardown after a timeout, or a call stuck in C code, has no bound. A test still running this
# long after its own timeout is hung: print every thread's stack and end the run, so that it
# fails showing where it hung instead of running until the CI's own limit.
HUNG_AFTER_TIMEOUT_S = 300


def _end_hung_run(item, after_s: float) -> None:
    capture = item.config.pluginmanager.getplugin("capturemanager")
    if capture is not None:
        capture.suspend_global_capture(in_=True)
    print(f"\n{item.nodeid} still running {after_s:.0f} s after it started: hung; every thread's stack:",
          file=sys.stderr, flush=True)
    faulthandler.dump_traceback(file=sys.stderr, all_threads=True)
    sys.stderr.flush()
    os._exit(1)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    marker = item.get_closest_marker("timeout")
    timeout_s = float(marker.args[0]) if marker and marker.args else float(item.config.getini("timeout") or 0)
    watchdog = None
    if timeout_s > 0:
        watchdog = threading.Timer(timeout_s + HUNG_AFTER_TIMEOUT_S, _end_hung_run,
                                   (item, timeout_s + HUNG_AFTER_TIMEOUT_S))
        watchdog.daemon = True
        watchdog.start()
    try:
        yield
    finally:
        if watchdog is not None:
            watchdog.cancel()


@pytest.fixture
def ros_domain():
    lease = DomainLease()
    yield lease.domain_id
    lease.release()


@pytest.fixture
def launcher(ros_domain, tmp_path):
    launcher = Launcher(ros_domain, tmp_path)
    yield launcher
    launcher.stop_all()


@pytest.fixture
def graph(ros_domain):
    graph = Graph(ros_domain)
    yield graph
    graph.close()
