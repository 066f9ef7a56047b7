"""Shared fixtures. Integration tests get a private ROS domain, a process launcher that
always cleans up, and an in-test graph node; see harness.py."""
import os

import pytest

from harness import DomainLease, Graph, Launcher

if not os.environ.get("BALL_BALANCE_ROOT"):
    raise pytest.UsageError("run the tests through scripts/test.sh (or `source env.sh` first)")

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_LOCALHOST_ONLY", None)


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
