"""Fixtures for node tests: the installed executable as a real subprocess, real DDS, rclpy.

Each test gets its own ROS_DOMAIN_ID and localhost-only discovery, so parallel runs and other
ROS users on the machine never see each other. The node process is always stopped (by PID)
when the test ends, pass or fail, and its log is attached to a failure message.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import yaml
from ament_index_python.packages import PackageNotFoundError, get_package_prefix

REPO = Path(__file__).resolve().parents[2]


def installed_executable(name: str) -> Path:
    """``lib/ssi_bridge/<name>`` of the ssi_bridge the environment has sourced, found the way
    ``ros2 run`` finds it (the ament index): this repository's install/ under `make test`,
    the workspace's install/ under `colcon test`."""
    try:
        prefix = Path(get_package_prefix("ssi_bridge"))
    except PackageNotFoundError:
        pytest.fail("ssi_bridge is not installed in the sourced environment: run `make setup` "
                    "and `source scripts/env.sh` (make test does both), or source a workspace's "
                    "install/setup.bash")
    exe = prefix / "lib" / "ssi_bridge" / name
    if not exe.exists():
        pytest.fail(f"{exe} missing: rebuild (make setup, or colcon build)")
    return exe


@dataclass
class NodeProcess:
    """A running ssi_bridge_node subprocess and the DDS domain it lives in."""

    proc: subprocess.Popen
    domain_id: int
    namespace: str
    log_path: Path
    name: str = "ssi_bridge"
    env: dict[str, str] = field(default_factory=dict)

    def topic(self, relative: str) -> str:
        """Resolve ``~/x`` and ``x`` the way the node does."""
        ns = self.namespace.rstrip("/")
        if relative.startswith("~/"):
            return f"{ns}/{self.name}/{relative[2:]}"
        if relative.startswith("/"):
            return relative
        return f"{ns}/{relative}"

    def log(self) -> str:
        """Everything the node printed so far."""
        return self.log_path.read_text(errors="replace") if self.log_path.exists() else ""

    def wait_for_log(self, text: str, timeout: float = 60.0) -> None:
        """Readiness from the node's own log (no DDS discovery needed): wait for ``text``."""
        deadline = time.monotonic() + timeout
        while text not in self.log():
            if self.proc.poll() is not None:
                pytest.fail(f"node exited {self.proc.returncode} before {text!r}:\n{self.log()}")
            if time.monotonic() > deadline:
                pytest.fail(f"no {text!r} within {timeout} s:\n{self.log()[-3000:]}")
            time.sleep(0.005)

    def stop(self, sig: int = signal.SIGINT, timeout: float = 10.0) -> int:
        """Stop the process (SIGINT, then SIGKILL after ``timeout``); returns the exit code."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        return self.proc.returncode


def dds_env(domain_id: int) -> dict[str, str]:
    """The environment of an isolated DDS domain on this host."""
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_LOCALHOST_ONLY", None)
    env["PYTHONUNBUFFERED"] = "1"
    return env


@pytest.fixture
def domain_id(monkeypatch: pytest.MonkeyPatch, ros_domain: int) -> int:
    """A test-unique ROS_DOMAIN_ID, also set for this process's rclpy context."""
    dom = ros_domain
    monkeypatch.setenv("ROS_DOMAIN_ID", str(dom))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    return dom


@pytest.fixture
def node_exe() -> Path:
    """The installed node executable (for tests that start it themselves)."""
    return installed_executable("ssi_bridge_node")


@pytest.fixture
def node_env(domain_id: int) -> dict[str, str]:
    """The environment of a node in the test's DDS domain."""
    return dds_env(domain_id)


def _then(first: Callable[[], None], second: Callable[[], None] | None) -> Callable[[], None]:
    """A preexec_fn running ``first`` (die with the test, SIGINT default) then ``second``."""
    if second is None:
        return first

    def both() -> None:
        first()
        second()

    both.dies_with_parent = True  # type: ignore[attr-defined]
    return both


@pytest.fixture
def start_node(tmp_path: Path, domain_id: int,
               child_preexec: Callable[[], None]) -> Iterator[Callable[..., NodeProcess]]:
    """Factory: start the installed node with parameters; every started node is stopped.

    Every node dies with the test process (PR_SET_PDEATHSIG) and handles SIGINT; ``preexec``
    runs after that in the child (e.g. a resource limit).
    """
    node_exe = installed_executable("ssi_bridge_node")
    started: list[NodeProcess] = []

    def _start(params: dict[str, Any] | None = None, *, namespace: str = "",
               params_file: Path | None = None, args: tuple[str, ...] = (),
               preexec: Callable[[], None] | None = None) -> NodeProcess:
        index = len(started)
        cmd = [str(node_exe), "--ros-args"]
        if params_file is not None:
            cmd += ["--params-file", str(params_file)]
        values = {"bus.channel": f"test_{domain_id}_{index}",
                  "storage_path": str(tmp_path / f"bank{index}" / "retentive.json")}
        values.update(params or {})
        pfile = tmp_path / f"params{index}.yaml"
        pfile.write_text(yaml.safe_dump({"/**": {"ros__parameters": values}}))
        cmd += ["--params-file", str(pfile)]
        if namespace:
            cmd += ["-r", f"__ns:={namespace}"]
        cmd += list(args)
        log_path = tmp_path / f"node{index}.log"
        env = dds_env(domain_id)
        with open(log_path, "wb") as log:
            proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env,
                                    cwd=tmp_path, start_new_session=True,
                                    preexec_fn=_then(child_preexec, preexec))
        node = NodeProcess(proc, domain_id, namespace, log_path, env=env)
        started.append(node)
        return node

    yield _start
    for node in started:
        code = node.stop()
        if code not in (0, None) and code != -signal.SIGKILL:
            print(f"node exited {code}; log:\n{node.log()[-4000:]}")


class RosProbe:
    """The test's own rclpy node in the test's domain, spinning in a background thread."""

    def __init__(self, domain_id: int) -> None:
        import threading

        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(f"probe_{os.getpid()}", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        from rclpy.executors import ExternalShutdownException
        try:
            self.executor.spin()
        except (ExternalShutdownException, Exception):  # noqa: BLE001 - ends with the test
            pass

    def subscribe(self, msg_type: Any, topic: str, qos: int = 50) -> list[tuple[float, Any]]:
        """Collect (receive time.monotonic(), message) of ``topic`` into a list."""
        received: list[tuple[float, Any]] = []
        self.node.create_subscription(msg_type, topic,
                                      lambda m: received.append((time.monotonic(), m)), qos)
        return received

    def wait_for(self, predicate: Callable[[], bool], timeout: float, what: str,
                 node: NodeProcess | None = None) -> None:
        """Poll ``predicate`` until true; fail with ``what`` (and the node log) on timeout."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return
            if node is not None and node.proc.poll() is not None:
                pytest.fail(f"node exited {node.proc.returncode} while waiting for {what}:\n"
                            f"{node.log()[-4000:]}")
            time.sleep(0.02)
        log = f"\nnode log:\n{node.log()[-4000:]}" if node is not None else ""
        pytest.fail(f"timed out after {timeout} s waiting for {what}{log}")

    def call(self, srv_type: Any, name: str, request: Any, timeout: float = 10.0) -> Any:
        """Call a service and return its response; fails the test on timeout."""
        import threading

        client = self.node.create_client(srv_type, name)
        try:
            assert client.wait_for_service(timeout_sec=timeout), f"service {name} not available"
            future = client.call_async(request)
            done = threading.Event()
            future.add_done_callback(lambda _f: done.set())
            assert done.wait(timeout), f"service {name} did not answer within {timeout} s"
            return future.result()
        finally:
            self.node.destroy_client(client)

    def close(self) -> None:
        """Shut the context down and join the spin thread."""
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.context.try_shutdown()
        self._thread.join(5.0)


@pytest.fixture
def probe(domain_id: int) -> Iterator[RosProbe]:
    """An rclpy node in the test's domain; closed after the test."""
    p = RosProbe(domain_id)
    yield p
    p.close()


@pytest.fixture
def running(start_node: Callable[..., NodeProcess], probe: RosProbe) -> Callable[..., NodeProcess]:
    """Factory: start a node and wait until its first joint_states message arrives."""
    from sensor_msgs.msg import JointState

    def _run(params: dict[str, Any] | None = None, **kwargs: Any) -> NodeProcess:
        node = start_node(params, **kwargs)
        seen = probe.subscribe(JointState, node.topic("joint_states"))
        probe.wait_for(lambda: len(seen) > 0, 30.0, "the first joint_states message", node)
        return node

    return _run


# -- /diagnostics and fault injection, as the node tests read and drive them ---------------------
def latest_status(diags: list[tuple[float, Any]], name: str) -> Any:
    """The newest DiagnosticStatus called ``name`` among received DiagnosticArrays, or None."""
    for _, arr in reversed(diags):
        for st in arr.status:
            if st.name == name:
                return st
    return None


def wait_for_level(probe: "RosProbe", node: NodeProcess, diags: list[tuple[float, Any]],
                   name: str, level: bytes, timeout: float) -> None:
    """Wait until the newest status ``name`` has ``level``."""
    probe.wait_for(lambda: (st := latest_status(diags, name)) is not None and st.level == level,
                   timeout, f"{name} at level {level!r}", node)


def inject(probe: "RosProbe", node: NodeProcess, **fields: Any) -> Any:
    """Call ``~/inject_fault`` with ``fields``; the reply, which must be a success."""
    from ssi_bridge_msgs.srv import InjectFault

    res = probe.call(InjectFault, node.topic("~/inject_fault"), InjectFault.Request(**fields))
    assert res.success, res.message
    return res
