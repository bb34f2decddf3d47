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
import threading
import time
from collections.abc import Callable
from typing import Any

import can
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.msg import Status
from ssi_bridge_msgs.srv import InjectFault, SdoRead

from ssi_bridge.base.udp_bus import open_udp_bus
from support.truth import TruthOracle, samples_from_joint_states

from .conftest import inject, latest_status, station_channel, station_pid, wait_for_level

K = InjectFault.Request
RATE = 200.0
#: bench/bench_truth.py sets this: each case appends its figures there as a JSON line
REPORT_ENV = "SSI_BRIDGE_TRUTH_REPORT"
SIM_EPOCH = 0x4004  # simulation only: the station's motion epoch, UNSIGNED64 us


def _params(channel: str, **extra: Any) -> dict[str, Any]:
    return {"joints": ["joint1"], "publish_rate": RATE, "bus.channel": channel,
            "diagnostics_period": 0.25, **extra}


def _epoch(probe, node) -> float:
    res = probe.call(SdoRead, node.topic("~/sdo_read"),
                     SdoRead.Request(index=SIM_EPOCH, subindex=0, data_type="UNSIGNED64"))
    assert res.success, res.message
    return res.unsigned_value / 1e6


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
        wait_for_level(probe, self.node, self.diags, "/ssi_bridge: joint1", DiagnosticStatus.OK,
                       20.0)
        self.oracle = TruthOracle.from_params(params, _epoch(probe, self.node))
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
                if st.name in ("/ssi_bridge: joint1", "/ssi_bridge: bus")
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
                for ch in m.channels if ch.joint == "joint1" and not ch.published}

    def worst_level_during(self, t0: float, t1: float) -> int:
        levels = [st.level for t, arr in self.diags if t0 <= t <= t1 for st in arr.status
                  if st.name == "/ssi_bridge: joint1"]
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
