"""Every published sample is true at its stamp, in process: the bridge under disturbance held
to the truth (docs/node.md, "Which cycle a TPDO answers"; support/truth.py).

Each ``joint_states`` position is the encoder's position at ``header.stamp`` within one count
plus the stated bound, each finite velocity within docs/node.md's velocity bound. Moved from
test/ros/test_node_truth.py (docs/testing.md): another producer's SYNCs on the bus, one stray
SYNC, CAN frame loss, REG_OFFSET written during motion; the node keeps what needs its process
(a stalled station process, the lifecycle) or its /diagnostics timing.
"""

from __future__ import annotations

import threading
import time

import can
import pytest

from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import open_bus
from ssi_bridge.sim.gateway.simulation import FaultKind as K
from support.inprocess_truth import RATE, TruthRun
from support.node_changes import hold_changes, timed
from support.truth import TruthOracle
from support.virtual_bus import send_syncs

PARAMS = {"joints": ["joint1"], "publish_rate": RATE}


def _run(inprocess) -> TruthRun:
    return TruthRun(inprocess(PARAMS), PARAMS)


def _foreign_syncs(channel: str, rate: float, seconds: float, stop: threading.Event) -> int:
    """SYNC (0x080) at ``rate`` Hz for ``seconds`` from another producer on the bus."""
    return send_syncs(open_bus(BusConfig(interface="virtual", channel=channel)), rate, seconds,
                      stop)


@pytest.mark.parametrize("rate,seconds", [(10.0, 2.0)])
def test_a_second_sync_producer_never_publishes_a_foreign_latch(inprocess, rate, seconds):
    """Another producer's SYNCs (CiA 301 allows one producer): the station answers them too,
    each answer latched at that SYNC. None is published as the master's cycle; the bus says
    so; the joint is published again once they stop."""
    run = _run(inprocess)
    b = run.b
    stop = threading.Event()
    seen: list[str] = []

    def watch() -> None:  # what the node's bus status says meanwhile (its findings' text)
        while not stop.is_set():
            seen.append(b.master.foreign_traffic(0.5))
            time.sleep(0.05)

    watcher = threading.Thread(target=watch)
    watcher.start()
    try:
        sent = _foreign_syncs(b.bus.channel, rate, seconds, threading.Event())
    finally:
        stop.set()
        watcher.join()
    t1 = time.time()
    assert sent >= 0.1 * rate * seconds
    b.run_until(lambda: b.joint_states()[-1][0] > t1 + 0.5, 10.0,
                "joint_states again after the disturbance")
    run.check(f"foreign_sync_{rate:g}hz")
    assert b.client.counters.foreign_syncs > 0, "foreign_syncs counted"
    assert any("another producer" in m for m in seen), seen[-3:]


def test_one_stray_sync_is_set_aside_for_the_cycles_it_touches(inprocess):
    run = _run(inprocess)
    bus = open_bus(BusConfig(interface="virtual", channel=run.b.bus.channel))
    try:
        bus.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
    finally:
        bus.shutdown()
    time.sleep(1.0)
    run.check("one_stray_sync")


@pytest.mark.parametrize("rate", [0.1])
def test_can_frame_loss_never_publishes_an_old_latch(inprocess, rate):
    run = _run(inprocess)
    w0 = time.time()
    run.b.bridge.inject_fault(run.b.bridge.joint(""), int(K.CAN_FRAME_LOSS), rate, 2.0)
    time.sleep(2.5)
    run.check(f"frame_loss_{rate:g}")
    assert run.set_aside_during(w0, w0 + 2.5), "lost frames leave cycles out"


def test_reg_offset_written_during_motion_moves_the_truth_at_the_call(inprocess):
    """REG_OFFSET itself (~/write_register address 50, 000 "Offset function": REG_SSI_POS =
    encoder - REG_OFFSET) written three times while the shaft turns: the samples stamped
    before a write hold the rule against the offset before it, those after it returned
    against the new one, those during it against either."""
    run = _run(inprocess)
    b = run.b
    time.sleep(0.5)
    t0 = time.monotonic()
    changes = []
    for offset in (-1000, 2000, 0):
        change, _ = timed(run, f"REG_OFFSET := {offset}", lambda o=offset: b.bridge.write_register(
            b.bridge.joint("joint1"), 50, o & 0xFFFF_FFFF),
            lambda _r, o=offset: TruthOracle.from_params(PARAMS, run.epochs, offsets={"joint1": o}))
        changes.append(change)
        time.sleep(0.5)
    hold_changes(run, changes, "reg_offset_during_motion", t0)
