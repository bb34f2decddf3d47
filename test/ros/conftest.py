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
from pathlib import Path
from typing import Any

import pytest
import yaml

from support.node_truth import latest_status
from support.ros_process import NodeProcess, dds_env, installed_executable  # noqa: F401

REPO = Path(__file__).resolve().parents[2]


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


def launch_node(workdir: Path, domain_id: int, index: int, preexec: Callable[[], None],
                params: dict[str, Any] | None = None, *, namespace: str = "",
                params_file: Path | None = None, args: tuple[str, ...] = ()) -> NodeProcess:
    """Start the installed node in ``domain_id`` with its files (params, log, register bank)
    under ``workdir``; ``index`` keeps the bus channel and files of several nodes apart."""
    cmd = [str(installed_executable("ssi_bridge_node")), "--ros-args"]
    if params_file is not None:
        cmd += ["--params-file", str(params_file)]
    values = {"bus.channel": f"test_{domain_id}_{index}",
              "storage_path": str(workdir / f"bank{index}" / "retentive.json")}
    values.update(params or {})
    pfile = workdir / f"params{index}.yaml"
    pfile.write_text(yaml.safe_dump({"/**": {"ros__parameters": values}}))
    cmd += ["--params-file", str(pfile)]
    if namespace:
        cmd += ["-r", f"__ns:={namespace}"]
    cmd += list(args)
    log_path = workdir / f"node{index}.log"
    env = dds_env(domain_id)
    with open(log_path, "wb") as log:
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env,
                                cwd=workdir, start_new_session=True, preexec_fn=preexec)
    return NodeProcess(proc, domain_id, namespace, log_path, env=env)


def _stop_and_report(node: NodeProcess) -> None:
    code = node.stop()
    if code not in (0, None) and code != -signal.SIGKILL:
        print(f"node exited {code}; log:\n{node.log()[-4000:]}")


@pytest.fixture
def start_node(tmp_path: Path, domain_id: int,
               child_preexec: Callable[[], None]) -> Iterator[Callable[..., NodeProcess]]:
    """Factory: start the installed node with parameters; every started node is stopped.

    Every node dies with the test process (PR_SET_PDEATHSIG) and handles SIGINT; ``preexec``
    runs after that in the child (e.g. a resource limit).
    """
    installed_executable("ssi_bridge_node")
    started: list[NodeProcess] = []

    def _start(params: dict[str, Any] | None = None, *, namespace: str = "",
               params_file: Path | None = None, args: tuple[str, ...] = (),
               preexec: Callable[[], None] | None = None) -> NodeProcess:
        node = launch_node(tmp_path, domain_id, len(started), _then(child_preexec, preexec),
                           params, namespace=namespace, params_file=params_file, args=args)
        started.append(node)
        return node

    yield _start
    for node in started:
        _stop_and_report(node)


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
        self._subscriptions: list[Any] = []
        #: exceptions of single executor wake-ups (the spinning went on)
        self.spin_errors: list[Exception] = []
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        """Spin until the context shuts down. An exception of one wake-up (rclpy may raise
        one when a client is destroyed from the test thread while the executor waits on it)
        is kept in :attr:`spin_errors` and the spinning goes on: before, it ended the thread
        silently, and every later test of a module sharing the probe saw no message."""
        from rclpy.executors import ExternalShutdownException, ShutdownException
        while self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=0.1)
            except (ExternalShutdownException, ShutdownException):
                return
            except Exception as err:  # noqa: BLE001 - reported, the probe goes on
                if not self.context.ok():
                    return
                self.spin_errors.append(err)
                print(f"probe executor: {err!r} (spinning on)")

    def subscribe(self, msg_type: Any, topic: str, qos: int = 50) -> list[tuple[float, Any]]:
        """Collect (receive time.monotonic(), message) of ``topic`` into a list."""
        received: list[tuple[float, Any]] = []
        self._subscriptions.append(self.node.create_subscription(
            msg_type, topic, lambda m: received.append((time.monotonic(), m)), qos))
        return received

    def subscribe_sent(self, msg_type: Any, topic: str, qos: int = 50) -> list[tuple[float, Any]]:
        """Collect (send time, message) of ``topic``: the send time is the DDS source
        timestamp the publisher put on it (wire time, s), so it tells when the node published
        a message however late a busy probe receives it."""
        received: list[tuple[float, Any]] = []
        self._subscriptions.append(self.node.create_subscription(
            msg_type, topic, lambda m, info: received.append((info["source_timestamp"] * 1e-9, m)),
            qos))
        return received

    def unsubscribe_since(self, count: int) -> None:
        """Destroy the subscriptions made after the first ``count`` (a test's own, on a probe
        shared by a module)."""
        while len(self._subscriptions) > count:
            self.node.destroy_subscription(self._subscriptions.pop())

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


# -- one node per module, for the tests that only read or call it ---------------------------
#: failed test phases so far in this process: a shared node handed out before a failure is
#: not handed out again (the failed test may have left it in any state)
_FAILURES = [0]
#: module name -> the running shared node of that module and its parameters
_SHARED: dict[str, dict[str, Any]] = {}


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """In each module, the tests that share its node run first, in file order: the node is
    started once for them and stopped before the module's other tests (which start their own
    nodes and should not share the CPU with an idle one)."""
    first = {id(item): "shared_node" in getattr(item, "fixturenames", ()) for item in items}
    order = {id(item): k for k, item in enumerate(items)}
    module_start: dict[str, int] = {}
    for k, item in enumerate(items):
        module_start.setdefault(item.nodeid.split("::")[0], k)
    items.sort(key=lambda item: (module_start[item.nodeid.split("::")[0]],
                                 not first[id(item)], order[id(item)]))


@pytest.fixture(autouse=True)
def _shared_node_only_while_used(request: pytest.FixtureRequest) -> None:
    """A test that does not use its module's shared node starts with that node stopped."""
    if "shared_node" in request.fixturenames:
        return
    state = _SHARED.get(request.module.__name__)
    if state and state.get("node") is not None:
        _stop_and_report(state.pop("node"))


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Any:
    report = yield
    if report.failed:
        _FAILURES[0] += 1
    return report


@pytest.fixture(scope="module")
def module_probe(module_domain: int) -> Iterator[RosProbe]:
    """The probe of the module's shared node (its domain); closed after the module."""
    p = RosProbe(module_domain)
    yield p
    p.close()


@pytest.fixture
def shared_probe(module_probe: RosProbe) -> Iterator[RosProbe]:
    """The module's probe for one test: the subscriptions the test makes end with it."""
    count = len(module_probe._subscriptions)
    yield module_probe
    module_probe.unsubscribe_since(count)


@pytest.fixture(scope="module")
def shared_node(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory,
                module_domain: int,
                module_child_preexec: Callable[[], None],
                module_probe: RosProbe) -> Iterator[Callable[..., NodeProcess]]:
    """Factory: the module's running node with these parameters, for tests that only read
    from it or call it without changing what another test of the module would see.

    A node is started (and its first joint_states awaited) once and handed to each following
    test that asks for the same parameters; asking for others stops it and starts a new one,
    so the module's domain holds one node at a time. After any failed test the next one gets a
    new node. Every node is stopped by PID at the end of the module, pass or fail.
    """
    from sensor_msgs.msg import JointState

    workdir = tmp_path_factory.mktemp("shared_node")
    started: list[NodeProcess] = []
    current: dict[str, Any] = _SHARED.setdefault(request.module.__name__, {})

    def _get(params: dict[str, Any] | None = None, *, namespace: str = "",
             params_file: Path | None = None) -> NodeProcess:
        key = (yaml.safe_dump(params or {}, sort_keys=True), namespace, str(params_file))
        node = current.get("node")
        if node is not None and current["key"] == key and current["failures"] == _FAILURES[0]:
            if node.proc.poll() is not None:
                pytest.fail(f"the module's shared node exited {node.proc.returncode} after an "
                            f"earlier test:\n{node.log()[-4000:]}")
            return node
        if node is not None:
            _stop_and_report(node)
        node = launch_node(workdir, module_domain, len(started), module_child_preexec, params,
                           namespace=namespace, params_file=params_file)
        started.append(node)
        current.update(node=node, key=key, failures=_FAILURES[0])
        count = len(module_probe._subscriptions)
        try:
            seen = module_probe.subscribe(JointState, node.topic("joint_states"))
            module_probe.wait_for(lambda: len(seen) > 0, 30.0,
                                  "the first joint_states message", node)
        finally:
            module_probe.unsubscribe_since(count)
        return node

    yield _get
    _SHARED.pop(request.module.__name__, None)
    for node in started:
        _stop_and_report(node)


# -- the simulated station's bus -------------------------------------------------------------------
def station_channel(bus_channel: str, domain_id: int) -> str:
    """The udp_multicast channel a default-named node with ``bus.channel`` = ``bus_channel`` in
    DDS domain ``domain_id`` shares with its simulated station child (the node's own rule)."""
    from ssi_bridge.ros.params import NodeSettings
    from ssi_bridge.sim.supervisor.station import with_station_bus

    return str(with_station_bus(NodeSettings(joints=(), bus_channel=bus_channel), domain=domain_id)
               .bus_channel)


# -- joint_states by joint name --------------------------------------------------------------------
def joint_of(msg: Any, name: str) -> tuple[float, float] | None:
    """(position, velocity) of joint ``name`` in a JointState, None when the cycle left it out
    (no sample latched at the stamp: docs/node.md)."""
    try:
        i = list(msg.name).index(name)
    except ValueError:
        return None
    return msg.position[i], msg.velocity[i]


# -- /diagnostics and fault injection, as the node tests read and drive them ---------------------
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
