"""replay: an rclpy subscriber receives every message in order; --rate 2 halves the time; /clock."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from .conftest import T0, joint_states_bag

N = 100           # messages, 10 ms apart: a 0.99 s bag
PERIOD_NS = 10_000_000


@pytest.fixture(scope="module")
def short_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return joint_states_bag(tmp_path_factory.mktemp("replay") / "short", N, period_ns=PERIOD_NS)


@pytest.fixture
def ros(monkeypatch: pytest.MonkeyPatch,
        ros_domain: int) -> Iterator[tuple[Context, dict[str, str]]]:
    """An rclpy context on a test-unique domain, and the matching subprocess environment."""
    domain = str(ros_domain)
    monkeypatch.setenv("ROS_DOMAIN_ID", domain)
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = Context()
    rclpy.init(context=context)
    yield context, dict(os.environ)
    rclpy.try_shutdown(context=context)


def replay(env: dict[str, str], bag: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """Run the replay executable (python -m, works before install/ is rebuilt); kill on fail."""
    proc = subprocess.Popen([sys.executable, "-m", "ssi_bridge.tools.replay", str(bag),
                             "--wait-for-subscribers", "20", "--quiet", *args],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    assert proc.returncode == 0, err
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def receive(context: Context, env: dict[str, str], bag: Path, topic: str, *args: str,
            ) -> tuple[list[tuple[float, JointState]], list[int]]:
    """Subscribe to ``topic`` (and /clock), run replay, return (arrival, msg) and clock ns."""
    node = rclpy.create_node("replay_probe", context=context)
    got: list[tuple[float, JointState]] = []
    clock: list[int] = []
    node.create_subscription(JointState, topic, lambda m: got.append((time.monotonic(), m)),
                             QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    node.create_subscription(Clock, "/clock",
                             lambda m: clock.append(m.clock.sec * 10**9 + m.clock.nanosec), 100)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    stop = threading.Event()
    spinner = threading.Thread(target=lambda: [executor.spin_once(0.01)
                                               for _ in iter(stop.is_set, True)])
    spinner.start()
    try:
        replay(env, bag, *args)
        deadline = time.monotonic() + 10
        while len(got) < N and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        stop.set()
        spinner.join()
        executor.shutdown()
        node.destroy_node()
    return got, clock


def test_every_message_in_order_rate_and_clock(short_bag: Path, ros) -> None:  # type: ignore[no-untyped-def]
    context, env = ros
    got, clock = receive(context, env, short_bag, "/replayed", "--remap",
                         "/joint_states:=/replayed", "--clock", "50")
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in got]
    assert stamps == [T0 + i * 1_000_000 for i in range(N)], f"{len(stamps)} of {N} received"
    assert [m.position[0] for _, m in got] == [0.001 * i for i in range(N)]
    span_1 = got[-1][0] - got[0][0]
    assert 0.85 < span_1 < 1.3, span_1
    assert len(clock) >= 20 and clock == sorted(clock)
    assert clock[0] <= T0 + 100 * PERIOD_NS // 10 and clock[-1] >= T0 + N * PERIOD_NS // 2

    got2, _ = receive(context, env, short_bag, "/joint_states", "--rate", "2")
    assert len(got2) == N
    span_2 = got2[-1][0] - got2[0][0]
    assert 0.4 < span_2 / span_1 < 0.6, (span_1, span_2)


@pytest.mark.parametrize(("make", "match"), [
    (lambda d: d / "missing", "no such bag"),
    (lambda d: d / "foreign.mcap", "not an MCAP file"),
    (lambda d: d / "truncated.mcap", "truncated"),
    (lambda d: d / "empty_dir", "neither metadata.yaml nor an .mcap"),
])
def test_clear_errors(tmp_path: Path, short_bag: Path, make, match: str) -> None:  # type: ignore[no-untyped-def]
    (tmp_path / "foreign.mcap").write_text("hello")
    data = (short_bag / "short_0.mcap").read_bytes()
    (tmp_path / "truncated.mcap").write_bytes(data[: len(data) // 2])
    (tmp_path / "empty_dir").mkdir()
    out = subprocess.run([sys.executable, "-m", "ssi_bridge.tools.replay",
                          str(make(tmp_path))], capture_output=True, text=True, timeout=60,
                         check=False)
    assert out.returncode == 2 and match in out.stderr, out.stderr
