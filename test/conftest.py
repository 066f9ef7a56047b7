"""Shared fixtures. Integration tests get a private ROS domain, a process launcher that
always cleans up, and an in-test graph node; see harness.py."""
import os
import signal

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
