"""Every published sample is true at its stamp: the node under disturbance, held to the truth.

The node's one promise (docs/node.md, "Which cycle a TPDO answers"): each ``joint_states``
position is the encoder's position at ``header.stamp`` within one count plus the bound the node
states (``latch_bound_s`` on the bus status), and each finite velocity is within docs/node.md's
velocity bound. For a simulated encoder the true motion is known: the truth oracle
(``test/support/truth.py``) takes the node's parameters and the station's motion epoch (object
0x4004, read over ``~/sdo_read``) and holds every published sample against it. Each case
disturbs the bus the way real buses are disturbed, and checks the rule with no exception, that
the disturbance shows in the same cycle's ``~/status`` and in ``/diagnostics``, and that the
joint is published again afterwards.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import can
import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.msg import Status
from ssi_bridge_msgs.srv import InjectFault, SdoRead

from ssi_bridge.base.udp_bus import open_udp_bus
from support.truth import TruthOracle, samples_from_joint_states

from .conftest import (REPO, inject, installed_executable, latest_status, station_channel,
                       station_pid, wait_for_level)

K = InjectFault.Request
RATE = 200.0
#: bench/bench_truth.py sets this: each case appends its figures there as a JSON line
REPORT_ENV = "SSI_BRIDGE_TRUTH_REPORT"
SIM_EPOCH = 0x4004  # simulation only: the station's motion epoch, UNSIGNED64 us


def _params(channel: str, **extra: Any) -> dict[str, Any]:
    return {"joints": ["joint1"], "publish_rate": RATE, "bus.channel": channel,
            "diagnostics_period": 0.25, **extra}


def _epochs(probe, node, stations: list[int]) -> dict[int, float]:
    """Each station's motion epoch (wire time, s) from object 0x4004 over ~/sdo_read."""
    out = {}
    for sid in stations:
        res = probe.call(SdoRead, node.topic("~/sdo_read"), SdoRead.Request(
            node_id=sid, index=SIM_EPOCH, subindex=0, data_type="UNSIGNED64"))
        assert res.success, res.message
        out[sid] = res.unsigned_value / 1e6
    return out


def _bus_values(diags) -> dict[str, str]:
    st = latest_status(diags, "/ssi_bridge: bus")
    return {kv.key: kv.value for kv in st.values} if st is not None else {}


class Run:
    """A node with subscriptions, its oracle and its stated bound."""

    def __init__(self, running: Callable[..., Any], probe, params: dict[str, Any]) -> None:
        self.probe, self.params = probe, params
        self.node = running(params)
        self.diags = probe.subscribe(DiagnosticArray, "/diagnostics")
        self.joints = probe.subscribe(JointState, self.node.topic("joint_states"), qos=2000)
        self.status = probe.subscribe(Status, self.node.topic("~/status"), qos=2000)
        names = list(params.get("joints", ["joint1"]))
        self.first = names[0]
        for name in names:
            wait_for_level(probe, self.node, self.diags, f"/ssi_bridge: {name}",
                           DiagnosticStatus.OK, 20.0)
        stations = sorted({int(params.get(f"{n}.station", 0)) or int(params.get("bus.node_id", 1))
                           for n in names})
        self.oracle = TruthOracle.from_params(params, _epochs(probe, self.node, stations))
        probe.wait_for(lambda: "latch_bound_s" in _bus_values(self.diags), 5.0,
                       "latch_bound_s on the bus status", self.node)
        self.bound = float(_bus_values(self.diags)["latch_bound_s"])

    def check(self, case: str = "", t0: float | None = None) -> None:
        """Every sample received so far holds the rule; it is a failure listing the worst.

        ``case``/``t0``: the disturbance's name and start (monotonic), for the bench's figures.
        """
        samples = samples_from_joint_states(m for _, m in self.joints)
        report = self.oracle.check(samples, self.bound)
        self._report(case, t0, report)
        assert report.checked > 0
        assert report.ok, report.summary()

    def _report(self, case: str, t0: float | None, report: Any) -> None:
        path = os.environ.get(REPORT_ENV)
        if not path or not case:
            return
        seen = [t for t, arr in self.diags if t0 is not None and t >= t0 for st in arr.status
                if st.name in (f"/ssi_bridge: {self.first}", "/ssi_bridge: bus")
                and st.level > DiagnosticStatus.OK]
        set_aside = max((ch.set_aside for _, m in self.status for ch in m.channels),
                        default=0)
        left_out = sum(1 for _, m in self.status for ch in m.channels if not ch.published)
        with open(path, "a", encoding="utf-8") as out:
            out.write(json.dumps({
                "case": case, "checked": report.checked,
                "worst_residual_counts": report.worst_residual_counts,
                "worst_velocity_error": report.worst_velocity_error,
                "violations": len(report.violations), "set_aside": set_aside,
                "left_out_cycles": left_out,
                "diagnostics_after_s": (min(seen) - t0) if seen and t0 is not None else None,
                "latch_bound_s": self.bound}) + "\n")

    def set_aside_during(self, t0: float, t1: float) -> set[str]:
        """The reasons ~/status gave for joint1 left out of cycles received in [t0, t1]."""
        return {ch.set_aside_reason for t, m in self.status if t0 <= t <= t1
                for ch in m.channels if ch.joint == self.first and not ch.published}

    def worst_level_during(self, t0: float, t1: float) -> int:
        levels = [st.level for t, arr in self.diags if t0 <= t <= t1 for st in arr.status
                  if st.name == f"/ssi_bridge: {self.first}"]
        return max(levels, default=DiagnosticStatus.OK)

    def published_again(self, after: float) -> None:
        self.probe.wait_for(lambda: any(t > after for t, _ in self.joints), 10.0,
                            "joint_states again after the disturbance", self.node)


@pytest.fixture
def channel(domain_id: int) -> str:
    """The node's bus.channel."""
    return f"truth_{domain_id}_{os.getpid()}"


@pytest.fixture
def wire(channel: str, domain_id: int) -> str:
    """The udp_multicast channel the node shares with its station: where another producer
    puts its frames."""
    return station_channel(channel, domain_id)


@pytest.mark.parametrize("seconds", [0.5, 2.0])
def test_a_stalled_station_never_publishes_an_old_latch(running, probe, channel, seconds):
    """The station process is paused (SIGSTOP) and resumed: its controller kept a few frames,
    it handles them late and answers; no answer is published under a stamp it was not
    latched at, the stall shows, and the joint is published again."""
    run = Run(running, probe, _params(channel))
    time.sleep(0.5)
    station = station_pid(run.node)
    t0 = time.monotonic()
    os.kill(station, signal.SIGSTOP)
    try:
        time.sleep(seconds)
    finally:
        os.kill(station, signal.SIGCONT)
    t1 = time.monotonic()
    run.published_again(t1 + 0.5)
    time.sleep(1.0)
    run.check(f"stall_{seconds:g}s", t0)
    assert run.set_aside_during(t0, t1) & {"no answer"}, "~/status says why during the stall"
    assert run.worst_level_during(t0, t1 + 0.5) > DiagnosticStatus.OK


def test_a_queueing_station_answering_its_backlog_never_publishes_an_old_latch(
        running, probe, channel):
    """A device that queues every SYNC answers a 1 s stall's backlog in a burst, each answer
    latched at its own SYNC: a surplus in the windows, set aside until it is in step."""
    run = Run(running, probe, _params(channel))
    inject(probe, run.node, kind=K.QUEUE_BACKLOG)
    time.sleep(0.5)
    station = station_pid(run.node)
    t0 = time.monotonic()
    os.kill(station, signal.SIGSTOP)
    try:
        time.sleep(1.0)
    finally:
        os.kill(station, signal.SIGCONT)
    t1 = time.monotonic()
    run.published_again(t1 + 0.5)
    time.sleep(1.0)
    run.check("queue_backlog_stall_1s", t0)
    reasons = run.set_aside_during(t1, t1 + 1.0)
    assert reasons, "the backlog's cycles are set aside"


def _foreign_syncs(wire: str, rate: float, seconds: float, stop: threading.Event) -> int:
    """Send SYNC (0x080) at ``rate`` Hz for ``seconds`` from another producer on ``wire``."""
    bus = open_udp_bus(wire)
    sent = 0
    try:
        start = time.monotonic()
        while not stop.is_set() and time.monotonic() - start < seconds:
            bus.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
            sent += 1
            time.sleep(max(0.0, start + sent / rate - time.monotonic()))
    finally:
        bus.shutdown()
    return sent


@pytest.mark.parametrize("rate,seconds", [(10.0, 2.0), (1000.0, 2.0)])
def test_a_second_sync_producer_never_publishes_a_foreign_latch(running, probe, channel, wire,
                                                                rate, seconds):
    """Another producer's SYNCs (CiA 301 allows one producer): the station answers them too,
    each answer latched at that SYNC. None is published as the master's cycle; the bus says
    so; the joint is published again once they stop."""
    run = Run(running, probe, _params(channel))
    stop = threading.Event()
    t0 = time.monotonic()
    try:
        sent = _foreign_syncs(wire, rate, seconds, stop)
    finally:
        stop.set()
    t1 = time.monotonic()
    assert sent >= 0.8 * rate * seconds
    run.published_again(t1 + 0.5)
    time.sleep(0.5)
    run.check(f"foreign_sync_{rate:g}hz", t0)
    probe.wait_for(lambda: int(_bus_values(run.diags).get("foreign_syncs", "0")) > 0, 5.0,
                   "foreign_syncs counted", run.node)
    warned = [st.message for t, arr in run.diags if t0 <= t <= t1 + 1.0 for st in arr.status
              if st.name == "/ssi_bridge: bus" and st.level >= DiagnosticStatus.WARN]
    assert any("another producer" in m for m in warned), warned[-3:]


def test_one_stray_sync_is_set_aside_for_the_cycles_it_touches(running, probe, channel, wire):
    run = Run(running, probe, _params(channel))
    bus = open_udp_bus(wire)
    t0 = time.monotonic()
    try:
        bus.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
    finally:
        bus.shutdown()
    time.sleep(1.0)
    run.check("one_stray_sync", t0)


@pytest.mark.parametrize("rate", [0.1])
def test_can_frame_loss_never_publishes_an_old_latch(running, probe, channel, rate):
    run = Run(running, probe, _params(channel))
    inject(probe, run.node, kind=K.CAN_FRAME_LOSS, rate=rate, duration=2.0)
    t0 = time.monotonic()
    time.sleep(2.5)
    run.check(f"frame_loss_{rate:g}", t0)
    assert run.set_aside_during(t0, t0 + 2.0), "lost frames leave cycles out"


# -- the slow tier: the rest of the matrix, one node through many disturbances ------------------
def _flat(values: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in values.items():
        if isinstance(value, dict):
            out.update(_flat(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def _two_stations(channel: str) -> dict[str, Any]:
    """The shipped two-station example (AFM60 sine, TTK70 linear, GENERIC on a second
    station), on this test's bus."""
    doc = yaml.safe_load((REPO / "config" / "ssi_bridge_two_stations.yaml").read_text())
    params = _flat(doc["/**"]["ros__parameters"])
    params.update({"bus.channel": channel, "publish_rate": RATE, "diagnostics_period": 0.25,
                   "simulation.transport": "udp_multicast"})
    return params


def _eight_joints(channel: str) -> dict[str, Any]:
    """Eight encoders on one station: rotary and linear, constant, reversed and sine."""
    names = [f"j{k}" for k in range(1, 9)]
    params: dict[str, Any] = {"joints": names, "publish_rate": RATE, "bus.channel": channel,
                              "diagnostics_period": 0.25}
    for k, name in enumerate(names, start=1):
        params[f"{name}.slot"] = k
        if k % 4 == 0:
            params.update({f"{name}.motion.kind": "sine", f"{name}.motion.amplitude": 0.3,
                           f"{name}.motion.frequency": 0.5})
        elif k % 4 == 1:
            params[f"{name}.motion.velocity"] = 0.1 * k
        elif k % 4 == 2:
            params.update({f"{name}.direction": -1, f"{name}.motion.velocity": 0.3})
        else:
            params.update({f"{name}.family": "TTK70", f"{name}.motion.velocity": 0.05})
    return params


def _nmt(wire: str, command: int, node_id: int) -> None:
    """One NMT command from another node on the bus (CiA 301 §7.2.8.3.1)."""
    bus = open_udp_bus(wire)
    try:
        bus.send(can.Message(arbitration_id=0x000, data=[command, node_id],
                             is_extended_id=False))
    finally:
        bus.shutdown()


def _set_rate(probe, node, rate: float) -> None:
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    res = probe.call(SetParameters, node.topic("~/set_parameters"), SetParameters.Request(
        parameters=[Parameter(name="publish_rate", value=ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE, double_value=rate))]))
    assert res.results[0].successful, res.results[0].reason


def _matrix(run: Run, wire: str, node_id: int) -> None:
    """Stalls, frame loss, NMT commands of another node, error frames, foreign SYNCs and a
    publish_rate change, one after the other, each followed by a recovery."""
    probe, node = run.probe, run.node
    station = station_pid(node)
    for seconds in (0.1, 0.5):
        os.kill(station, signal.SIGSTOP)
        time.sleep(seconds)
        os.kill(station, signal.SIGCONT)
        run.published_again(time.monotonic() + 0.3)
    for rate in (0.01, 0.5):
        inject(probe, node, kind=K.CAN_FRAME_LOSS, rate=rate, duration=1.5)
        time.sleep(2.0)
    for command in (0x02, 0x82, 0x80):  # stop, reset communication, pre-operational
        _nmt(wire, command, node_id)
        time.sleep(1.5)
        run.published_again(time.monotonic())
    for kind in (K.ERROR_PASSIVE, K.BUS_OFF):
        inject(probe, node, kind=kind, duration=1.0)
        time.sleep(2.5)
        run.published_again(time.monotonic())
    stop = threading.Event()
    _foreign_syncs(wire, 10.0, 1.0, stop)
    _foreign_syncs(wire, 1000.0, 1.0, stop)
    run.published_again(time.monotonic() + 0.5)
    _set_rate(probe, node, 500.0)
    time.sleep(1.0)
    _set_rate(probe, node, RATE)
    time.sleep(1.0)


def test_the_disturbance_matrix_on_two_stations_beside_two_burners(running, probe, channel,
                                                                   wire):
    """Rotary and linear, constant and sine, two stations; two CPU burners throughout."""
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        run = Run(running, probe, _two_stations(channel))
        t0 = time.monotonic()
        _matrix(run, wire, 1)
        run.check("matrix_two_stations_burners", t0)
    finally:
        for p in burners:
            os.kill(p.pid, signal.SIGKILL)
            p.wait(5)


def test_the_disturbance_matrix_on_eight_joints(running, probe, channel, wire):
    run = Run(running, probe, _eight_joints(channel))
    t0 = time.monotonic()
    _matrix(run, wire, 1)
    run.check("matrix_eight_joints", t0)


def test_a_station_killed_and_started_again_on_the_same_bus(start_node, probe, tmp_path,
                                                           domain_id):
    """A real-station set-up (simulation.enabled false): the standalone ``station`` program
    killed and another started on the same bus; its motion epoch is new."""
    channel = station_channel(f"restart_{domain_id}_{os.getpid()}", domain_id)
    params = {"joints": ["joint1"], "publish_rate": RATE, "diagnostics_period": 0.25,
              "simulation.enabled": False, "bus.interface": "udp_multicast",
              "bus.channel": channel}
    config = tmp_path / "station.yaml"
    config.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"joints": ["joint1"]}}}))

    def station() -> subprocess.Popen:
        proc = subprocess.Popen(
            [str(installed_executable("station")), "--params-file", str(config),
             "--interface", "udp_multicast", "--channel", channel],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        time.sleep(2.0)
        return proc

    first = station()
    second = None
    try:
        run = Run(lambda p: start_node(p), probe, params)
        time.sleep(0.5)
        t0 = time.monotonic()
        os.kill(first.pid, signal.SIGKILL)
        first.wait(5)
        cut = time.monotonic()
        time.sleep(0.5)
        second = station()
        run.published_again(time.monotonic() + 0.5)
        time.sleep(1.0)
        # the samples before the restart against the first station's epoch, after it against
        # the new one's
        before = [(t, m) for t, m in run.joints if t < cut]
        after = [(t, m) for t, m in run.joints if t > cut]
        run.joints[:] = before
        run.check("station_killed", t0)
        run.oracle = TruthOracle.from_params(params, _epochs(probe, run.node, [1]))
        run.joints[:] = after
        run.check("station_restarted", t0)
    finally:
        for proc in (first, second):
            if proc is not None and proc.poll() is None:
                os.kill(proc.pid, signal.SIGKILL)
                proc.wait(5)
