"""Integration-test harness: real processes on a private ROS domain, waited on, always cleaned up.

- `DomainLease` hands out a ROS_DOMAIN_ID no other test (in this run or a parallel one on
  the same machine) holds, using a lock file per id.
- `Launcher` starts executables as process groups with that domain and localhost-only
  discovery, logs their output to files, and stops every one of them at the end.
- `Graph` is an in-test rclpy node on the same domain, for waiting on topics, services and
  messages with deadlines instead of fixed sleeps.
"""
from __future__ import annotations

import fcntl
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable, List, Optional, Sequence

ROOT = Path(__file__).resolve().parents[1]
INSTALL_BIN = ROOT / "install" / "lib" / "ball_balance"
# ros2_control_node and spawner: `ros2 run controller_manager_py <name>`
CM_INSTALL_BIN = ROOT / "install" / "lib" / "controller_manager_py"
# ROS domain ids are the machine's, not this run's: their locks stay in /tmp whatever TMPDIR is,
# so that test runs with different TMPDIRs do not share a domain
LOCK_DIR = Path("/tmp/ball_balance_ros_domains")
DOMAIN_RANGE = range(30, 230)
# The project's DDS settings (docs/transport.md) for every process a test starts and for the
# test process itself (set before its first participant exists): tests run as users do.
DDS_ENV = {"FASTRTPS_DEFAULT_PROFILES_FILE": str(ROOT / "config" / "dds" / "fastdds.xml"),
           "FASTDDS_DEFAULT_PROFILES_FILE": str(ROOT / "config" / "dds" / "fastdds.xml"),
           "CYCLONEDDS_URI": f"file://{ROOT / 'config' / 'dds' / 'cyclonedds.xml'}"}
os.environ.update(DDS_ENV)


class DomainLease:
    """Exclusive use of one ROS_DOMAIN_ID while held (across processes on this machine).

    Each lease of a process starts its search one domain further than the last: a process that a
    test failed to stop then meets no other test of the run for a long while, not every one after it.
    """

    _leases = 0

    def __init__(self):
        LOCK_DIR.mkdir(exist_ok=True)
        start = (os.getpid() * 7 + DomainLease._leases) % len(DOMAIN_RANGE)
        DomainLease._leases += 1
        for offset in range(len(DOMAIN_RANGE)):
            domain = DOMAIN_RANGE[(start + offset) % len(DOMAIN_RANGE)]
            handle = open(LOCK_DIR / f"{domain}.lock", "w")
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                handle.close()
                continue
            self.domain_id, self._handle = domain, handle
            return
        raise RuntimeError("no free ROS_DOMAIN_ID for the test")

    def release(self):
        fcntl.flock(self._handle, fcntl.LOCK_UN)
        self._handle.close()


def ros_env(domain_id: int, **extra: str) -> dict:
    """The environment for a process on `domain_id`, discovering only on this machine."""
    env = dict(os.environ)
    env.pop("ROS_LOCALHOST_ONLY", None)
    env.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               PYTHONUNBUFFERED="1", RCUTILS_COLORIZED_OUTPUT="0", **DDS_ENV)
    env.update(extra)
    return env


def executable(name: str) -> str:
    """Path of one of our installed executables (`ros2 run ball_balance <name>`, or
    `ros2 run controller_manager_py <name>` for ros2_control_node and spawner)."""
    for folder in (INSTALL_BIN, CM_INSTALL_BIN):
        if (folder / name).exists():
            return str(folder / name)
    raise FileNotFoundError(f"{INSTALL_BIN / name} missing: run scripts/setup.sh")


class Process:
    def __init__(self, name: str, popen: subprocess.Popen, log_path: Path):
        self.name, self.popen, self.log_path = name, popen, log_path

    def output(self) -> str:
        return self.log_path.read_text(errors="replace") if self.log_path.exists() else ""

    def wait(self, timeout: float) -> int:
        return self.popen.wait(timeout=timeout)

    @property
    def running(self) -> bool:
        return self.popen.poll() is None


class Launcher:
    """Starts processes on a domain; `stop_all()` ends every one (SIGINT, then SIGKILL)."""

    def __init__(self, domain_id: int, log_dir: Path):
        self.domain_id, self.log_dir = domain_id, log_dir
        self.processes: List[Process] = []

    def start(self, cmd: Sequence[str], name: Optional[str] = None, env: Optional[dict] = None,
              cwd: Optional[Path] = None) -> Process:
        name = name or Path(cmd[0]).name
        log_path = self.log_dir / f"{name}-{len(self.processes)}.log"
        log = open(log_path, "wb")
        popen = subprocess.Popen(list(cmd), stdout=log, stderr=subprocess.STDOUT,
                                 stdin=subprocess.DEVNULL, cwd=cwd,
                                 env=env or ros_env(self.domain_id), start_new_session=True)
        log.close()
        process = Process(name, popen, log_path)
        self.processes.append(process)
        return process

    def run(self, cmd: Sequence[str], timeout: float = 60.0, env: Optional[dict] = None,
            input: Optional[str] = None) -> subprocess.CompletedProcess:
        """Run a command to completion on this domain (output captured as text).

        On a timeout the command's whole process group is stopped, not only the command: a
        script's nodes left running on this domain would answer the tests that lease it next.
        """
        popen = subprocess.Popen(list(cmd), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                 env=env or ros_env(self.domain_id), start_new_session=True,
                                 stdin=subprocess.PIPE if input is not None else subprocess.DEVNULL)
        try:
            stdout, stderr = popen.communicate(input, timeout=timeout)
        except subprocess.TimeoutExpired:
            stop_groups([popen])
            try:
                stdout, stderr = popen.communicate(timeout=10)
            except subprocess.TimeoutExpired:  # a process that left the group still holds a pipe
                stdout, stderr = "", ""
            raise subprocess.TimeoutExpired(popen.args, timeout, stdout, stderr) from None
        finally:
            _signal_group(popen, signal.SIGKILL)  # strays left in its group
        return subprocess.CompletedProcess(popen.args, popen.returncode, stdout, stderr)

    def stop_all(self, grace_s: float = 5.0) -> None:
        stop_groups([process.popen for process in self.processes], grace_s)


def stop_groups(popens: Sequence[subprocess.Popen], grace_s: float = 5.0) -> None:
    """Ctrl-C each process group (started with start_new_session), SIGKILL what is left after grace_s."""
    for popen in popens:
        if popen.poll() is None:
            _signal_group(popen, signal.SIGINT)
    deadline = time.monotonic() + grace_s
    for popen in popens:
        try:
            popen.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            pass
        if popen.poll() is None:
            _signal_group(popen, signal.SIGKILL)
            popen.wait(timeout=5)
        else:
            _signal_group(popen, signal.SIGKILL)  # strays left in its group


def _signal_group(popen: subprocess.Popen, sig: int) -> None:
    try:
        os.killpg(popen.pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


class Graph:
    """An rclpy node in the test process, on the test's domain, with deadline-based waits."""

    def __init__(self, domain_id: int, name: str = "test_graph"):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        os.environ.pop("ROS_LOCALHOST_ONLY", None)
        self.context = rclpy.Context()
        rclpy.init(args=[], context=self.context, domain_id=domain_id)  # not the caller's argv
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def wait_until(self, condition: Callable[[], bool], timeout: float, poll_s: float = 0.02) -> bool:
        """Spin until condition() holds (True) or timeout passes (False).

        condition() runs at most every poll_s: a condition that calls a service would otherwise flood
        it, and a server with real-time threads on the same CPU then starves everything else there.
        """
        deadline = time.monotonic() + timeout
        while True:
            if condition():
                return True
            next_check = time.monotonic() + poll_s
            while (now := time.monotonic()) < next_check:
                if now >= deadline:
                    return False
                self.executor.spin_once(timeout_sec=min(next_check, deadline) - now)

    def spin_until(self, condition: Callable[[], bool], timeout: float, what: str = "condition") -> None:
        if not self.wait_until(condition, timeout):
            raise TimeoutError(f"timed out after {timeout:.0f} s waiting for {what}")

    def wait_for_output(self, process: Process, pattern: str, timeout: float, what: str) -> str:
        """The first group of regex `pattern`'s first match in `process`'s output, spinning until it
        is there; the process dying first fails with its output."""
        found = []

        def printed() -> bool:
            assert process.running, process.output()[-3000:]
            found[:] = re.findall(pattern, process.output())
            return bool(found)
        self.spin_until(printed, timeout, what)
        return found[0]

    def spin_for(self, seconds: float) -> None:
        self.wait_until(lambda: False, seconds)

    def wait_for_topic(self, topic: str, timeout: float = 20.0) -> None:
        self.spin_until(lambda: any(n == topic for n, _ in self.node.get_topic_names_and_types()),
                        timeout, f"topic {topic}")

    def wait_for_service(self, service: str, timeout: float = 20.0) -> None:
        self.spin_until(lambda: any(n == service for n, _ in self.node.get_service_names_and_types()),
                        timeout, f"service {service}")

    def collect(self, msg_type, topic: str, count: int = 1, timeout: float = 20.0, qos=10,
                predicate: Callable = lambda m: True) -> list:
        """Subscribe to `topic` and return the first `count` messages that pass `predicate`."""
        received = []
        sub = self.node.create_subscription(
            msg_type, topic, lambda m: received.append(m) if predicate(m) else None, qos)
        try:
            self.spin_until(lambda: len(received) >= count, timeout, f"{count} message(s) on {topic}")
        finally:
            self.node.destroy_subscription(sub)
        return received[:count]

    def call(self, srv_type, service: str, request, timeout: float = 10.0):
        client = self.node.create_client(srv_type, service)
        try:
            self.spin_until(client.service_is_ready, timeout, f"service {service}")
            future = client.call_async(request)
            self.spin_until(future.done, timeout, f"response from {service}")
            return future.result()
        finally:
            self.node.destroy_client(client)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


def python_cmd(*args: str) -> List[str]:
    """Run a module or script with this test run's Python (the venv)."""
    return [sys.executable, *args]
