"""The CLI's own short-lived rclpy node: graph discovery, waiting, service calls, QoS.

ros2cli without its daemon creates a hidden node per command and lets discovery run for a
moment; so do we. The node is hidden (`_ros2py_<pid>`), serves no parameters and has no
/rosout publisher, so it does not show up in what it lists.
"""
from __future__ import annotations

import contextlib
import os
import signal
import time
from typing import Callable, Dict, Iterator, List, Optional, Tuple

from ball_balance.cli.errors import BadArgument, CliError

# Fast DDS sends 5 participant announcements at start, then one every 3 s, so a new
# participant often learns of the others only from their next periodic announcement (0-3 s
# later). With 20 initial announcements it mostly discovers them in about 0.15 s, and fewer
# `topic echo` runs are slow (benchmarks/cli_bench.py). Used only for our own short-lived
# participant, and only when the user has not chosen a Fast DDS profile.
FASTDDS_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <participant profile_name="ros2py" is_default_profile="true">
    <rtps><builtin><discovery_config>
      <initialAnnouncements><count>20</count><period><nanosec>100000000</nanosec></period></initialAnnouncements>
    </discovery_config></builtin></rtps>
  </participant>
</profiles>
"""


def use_fast_discovery_profile() -> None:
    """Point Fast DDS at FASTDDS_PROFILE (written once to the temp folder) for this process."""
    import tempfile

    if os.environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp") != "rmw_fastrtps_cpp":
        return
    if os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE") or os.environ.get("FASTDDS_DEFAULT_PROFILES_FILE"):
        return
    path = os.path.join(tempfile.gettempdir(), f"ros2py-fastdds-{os.getuid()}-v1.xml")
    if not os.path.exists(path):
        scratch = f"{path}.{os.getpid()}"
        with open(scratch, "w", encoding="utf-8") as handle:
            handle.write(FASTDDS_PROFILE)
        os.replace(scratch, path)
    os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = path


DEFAULT_SPIN_TIME_S = 3.0  # upper bound on discovery waits (no daemon keeps the graph for us)
# On the simulated graph under load, a busy participant (the controller manager with MuJoCo)
# answers our announcements up to about 1.7 s after the previous change to the graph, so a
# settle time of 1.0 or 1.5 s can list an incomplete graph. Listing verbs wait this long
# unchanged.
SETTLE_S = 2.0
# Our participant announces itself 20 times in its first 2 s (FASTDDS_PROFILE, and the
# project's config/dds/fastdds.xml, which replaces it under env.sh). A busy participant may
# answer only the last of them, so a graph that looks settled earlier can still lack nodes
# and endpoints. Listing verbs do not call the graph settled before this phase is over.
ANNOUNCE_PHASE_S = 2.0


# While the CLI's entry point runs a verb (teardowns_deferred), Session.close() leaves rclpy's
# teardown here, for the entry point to run once the verb's output is out, under a deadline:
# rclpy 7.1.6 can hang in Node.destroy_node (destroy_when_not_in_use) for many minutes. None:
# close() tears down at once.
_deferred_teardowns: Optional[List[Callable[[], None]]] = None


@contextlib.contextmanager
def teardowns_deferred() -> Iterator[List[Callable[[], None]]]:
    """Within: Session.close() appends its teardown to the list given, and the caller runs them."""
    global _deferred_teardowns
    outer, _deferred_teardowns = _deferred_teardowns, []
    try:
        yield _deferred_teardowns
    finally:
        _deferred_teardowns = outer


class Session:
    """`with Session() as s:` gives s.node, spun by s.spin_until(...)."""

    def __init__(self, spin_time_s: float = DEFAULT_SPIN_TIME_S, name: str = "ros2py"):
        """spin_time_s: how long waits for nodes and services may take (discovery)."""
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.spin_time_s = spin_time_s
        use_fast_discovery_profile()
        self.context = rclpy.Context()
        rclpy.init(args=[], context=self.context)
        self.node = rclpy.create_node(f"_{name}_{os.getpid()}", context=self.context,
                                      start_parameter_services=False, enable_rosout=False)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Tear rclpy down now, or leave that to the entry point (teardowns_deferred)."""
        if _deferred_teardowns is None:
            self.teardown()
        elif self.teardown not in _deferred_teardowns:
            _deferred_teardowns.append(self.teardown)

    def teardown(self) -> None:
        try:
            self.executor.shutdown(timeout_sec=0.5)
            self.node.destroy_node()
        except Exception:  # noqa: BLE001 - the context may already be shut down (Ctrl-C)
            pass
        finally:
            self.context.try_shutdown()

    # --- waiting -----------------------------------------------------------------------
    def spin_until(self, condition: Callable[[], bool], timeout_s: Optional[float],
                   step_s: float = 0.05) -> bool:
        """Spin until condition() is true (True) or timeout_s passes (False; None: forever)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not condition():
            step = step_s
            if deadline is not None:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                step = min(step_s, remaining)
            self.executor.spin_once(timeout_sec=step)
        return True

    def spin_for(self, duration_s: float) -> None:
        self.spin_until(lambda: False, duration_s)

    def discover(self, spin_time_s: float = DEFAULT_SPIN_TIME_S, settle_s: float = SETTLE_S) -> None:
        """Let discovery run until the graph stops changing for settle_s (at most spin_time_s).

        While only our own node is visible, keep waiting (for up to spin_time_s): another
        participant's first announcement can take 2 s to arrive on a loaded machine. A graph
        with endpoints whose node is not known yet (the participant's node list, sent on
        ros_discovery_info, lags its endpoints) is not settled either.
        """
        start = time.monotonic()
        state = {"seen": None, "since": start}

        def settled() -> bool:
            now = time.monotonic()
            topics = self.node.get_topic_names_and_types()
            snapshot = (tuple(sorted(self.node.get_node_names_and_namespaces())),
                        tuple((n, tuple(t)) for n, t in topics),
                        tuple((n, tuple(t)) for n, t in self.node.get_service_names_and_types()))
            if snapshot != state["seen"]:
                state["seen"], state["since"] = snapshot, now
            others = len(snapshot[0]) > 1
            return (others and now - state["since"] >= settle_s and now - start >= ANNOUNCE_PHASE_S
                    and not self._nameless_endpoints(topics))

        self.spin_until(settled, spin_time_s, step_s=0.1)

    def _nameless_endpoints(self, topics) -> bool:
        """True while some endpoint's node is still unknown (its participant is half discovered)."""
        for name, _ in topics:
            for endpoint in (*self.node.get_publishers_info_by_topic(name),
                             *self.node.get_subscriptions_info_by_topic(name)):
                if endpoint.node_name.startswith("_NODE_NAME_UNKNOWN_"):
                    return True
        return False

    # --- graph -------------------------------------------------------------------------
    def topic_types(self) -> Dict[str, List[str]]:
        return dict(self.node.get_topic_names_and_types())

    def wait_for_topic_type(self, topic: str, timeout_s: float) -> Optional[str]:
        """The type of `topic` once the graph shows it (None after timeout_s)."""
        found: List[str] = []

        def appeared() -> bool:
            types = self.topic_types().get(topic)
            if types:
                found.append(types[0])
            return bool(found)

        self.spin_until(appeared, timeout_s)
        return found[0] if found else None

    def node_exists(self, full_name: str) -> bool:
        return any(_join(ns, name) == full_name for name, ns in self.node.get_node_names_and_namespaces())

    def wait_for_node(self, full_name: str, timeout_s: float) -> None:
        if not self.spin_until(lambda: self.node_exists(full_name), timeout_s):
            raise CliError(f"node '{full_name}' not found (waited {timeout_s:.1f} s); see `ros2py node list`")

    def call(self, srv_type, service: str, request, timeout_s: float = 10.0):
        """Call a service and return the response, or raise a CliError naming the service."""
        client = self.node.create_client(srv_type, service)
        try:
            self.wait_for_service(client, timeout_s)
            return self.request(client, request, timeout_s)
        finally:
            self.node.destroy_client(client)

    def wait_for_service(self, client, timeout_s: Optional[float]) -> None:
        """Until the client's service is there (None: forever), else a CliError naming it."""
        if not self.spin_until(client.service_is_ready, timeout_s):
            raise CliError(f"service '{client.service_name}' is not available (waited {timeout_s:.1f} s)")

    def request(self, client, request, timeout_s: Optional[float]):
        """One call through `client`: the response (None: wait forever), else a CliError naming it."""
        future = client.call_async(request)
        if not self.spin_until(future.done, timeout_s):
            raise CliError(f"no response from service '{client.service_name}' within {timeout_s:.1f} s")
        if future.exception() is not None:
            raise CliError(f"service '{client.service_name}' failed: {future.exception()}")
        return future.result()

    def adapted_qos(self, topic: str, reliability: Optional[str] = None, durability: Optional[str] = None,
                    depth: int = 10):
        """A subscription QoS that matches every publisher on `topic` (as ros2 topic echo does).

        Reliable only if every publisher is (best effort, which matches any publisher, when
        none is known yet), transient local only if all publishers are;
        explicit `reliability`/`durability` ('reliable', 'best_effort', 'volatile',
        'transient_local') win.
        """
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        publishers = self.node.get_publishers_info_by_topic(topic)
        rel = ReliabilityPolicy.BEST_EFFORT  # with no publisher known yet: matches any late one
        dur = DurabilityPolicy.VOLATILE
        if publishers:
            if all(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in publishers):
                rel = ReliabilityPolicy.RELIABLE
            if all(p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publishers):
                dur = DurabilityPolicy.TRANSIENT_LOCAL
        if reliability:
            rel = ReliabilityPolicy[reliability.upper()]
        if durability:
            dur = DurabilityPolicy[durability.upper()]
        return QoSProfile(depth=depth, reliability=rel, durability=dur)


def _join(namespace: str, name: str) -> str:
    return f"{namespace.rstrip('/')}/{name}"


def absolute_name(name: str) -> str:
    """'talker' -> '/talker'; '/ns/talker' stays (node and topic names alike)."""
    return name if name.startswith("/") else f"/{name}"


full_node_name = absolute_name


def valid_name(name: str, kind: str = "topic") -> str:
    """The absolute form of a topic, service or action name (kind), checked as rcl checks it
    before anything is created with it; else a BadArgument naming it and what is wrong (rcl's
    own error, raised later, ends with its C source location, and rclpy's spans three lines)."""
    from rclpy.impl.implementation_singleton import rclpy_implementation

    full = absolute_name(name)
    problem = rclpy_implementation.rclpy_get_validation_error_for_topic_name(name)
    if problem is None:
        problem = rclpy_implementation.rclpy_get_validation_error_for_full_topic_name(full)
        if problem is None:
            return full
        if "~" in name or "{" in name:
            problem = ("'~' and '{...}' substitutions are not expanded by ros2py: give the full name", None)
        else:  # the place in `full`, which may have a '/' more in front
            problem = (problem[0], problem[1] - (len(full) - len(name)))
    why, index = problem
    # rcl says "topic name ..." of every kind of name
    why = why.replace("topic name token", "a token").replace("topic name", "it")
    at = f" (character {index + 1}: {name[index]!r})" if index is not None and 0 <= index < len(name) else ""
    raise BadArgument(f"'{name}' is not a valid {kind} name: {why}{at}")


def is_hidden(name: str) -> bool:
    """ROS hides names with a token starting with '_' (our own node among them)."""
    return any(part.startswith("_") for part in name.split("/"))


def node_names(session: Session, include_hidden: bool = False) -> List[str]:
    names = {_join(ns, name) for name, ns in session.node.get_node_names_and_namespaces()}
    return sorted(n for n in names if include_hidden or not is_hidden(n))


def name_type_pairs(pairs: List[Tuple[str, List[str]]], include_hidden: bool = False):
    return sorted((name, types) for name, types in pairs if include_hidden or not is_hidden(name))


def print_name_type_pairs(pairs: List[Tuple[str, List[str]]], count_only: bool, show_types: bool) -> int:
    """Print as `ros2 topic list` / `ros2 service list` do: the count, or one name per line."""
    if count_only:
        print(len(pairs))
        return 0
    for name, types in pairs:
        print(f"{name} [{', '.join(types)}]" if show_types else name)
    return 0


class StopRequest:
    """SIGINT (Ctrl-C) and SIGTERM ask a long-running verb (bag record, bag play) to stop; its
    main loop looks between naps.

    Raising KeyboardInterrupt from the handler would land wherever the main thread happens to
    be, and one raised inside a __del__ run by the garbage collector is printed and dropped (a
    recording would go on). The handler only sets a flag: no lock, so it cannot deadlock on one
    the main thread holds. A second signal while a file is being finished does nothing."""

    NAP_S = 0.05

    def __init__(self):
        self.requested = False
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._on_signal)

    def _on_signal(self, signum, frame) -> None:
        self.requested = True

    def sleep_until(self, end_s: float) -> bool:
        """Sleep until time.monotonic() reaches end_s or a stop is asked for (True)."""
        while not self.requested:
            left_s = end_s - time.monotonic()
            if left_s <= 0.0:
                break
            time.sleep(min(left_s, self.NAP_S))
        return self.requested
