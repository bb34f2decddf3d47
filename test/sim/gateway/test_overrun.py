"""A gateway that stalls: its controller's FIFO overruns (CiA 301 EMCY 0x8110), a SYNC handled
late latches when handled, and QUEUE_BACKLOG answers every SYNC instead.

The station runs in this process on a private virtual bus with a handling grace of 5 ms (a
station in its master's process has none by default: its delays are the process's); the test
stalls it by holding the gateway's lock, as a starved firmware would be held, while canopen's
own master sends SYNCs. CiA 301: EMCY 0x8110 "CAN overrun (objects lost)", error register
bit 4 "communication error", the error-reset EMCY 0x0000 once no error is left.
"""

from __future__ import annotations

import struct
import time
from collections.abc import Iterator

import pytest

from ssi_bridge.base.timebase import wire_now
from ssi_bridge.protocol.dictionary import SIM_COMMAND
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.controller import RX_FIFO_DEPTH
from ssi_bridge.sim.gateway.gateway import XnGateway
from ssi_bridge.sim.gateway.simulation import FaultKind, SimulationControl, command_word
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

from support.virtual_bus import ScriptedReader
from support.waiting import wait_for

from .conftest import NODE_ID, Station, canopen_master

GRACE = 0.005
STALL_SYNCS = 20
GAP = 0.002  # between the SYNCs sent during the stall: 40 ms in all, 8 graces


@pytest.fixture
def stalling(channel: str) -> Iterator[Station]:
    """A one-slot station with a 5 ms grace, PRE-OPERATIONAL, with a canopen master."""
    reader = ScriptedReader(1234)
    gateway = XnGateway(BusConfig(channel=channel, node_id=NODE_ID), NODE_ID,
                        [Xn1Ssi(reader, slot=1)])
    gateway.stall_grace = GRACE
    control = SimulationControl(_NoChannels(), gateway)
    gateway.start()
    try:
        with canopen_master(channel, 1) as (network, node):
            try:
                yield Station(gateway, network, node, [reader])
            finally:
                control.stop()
    finally:
        gateway.stop()


class _NoChannels:
    def channel_in_slot(self, slot: int) -> None:
        return None


def _stall(st: Station) -> tuple[int, float, float]:
    """Hold the gateway for STALL_SYNCS SYNCs; returns (cycles run before, wire time of the
    last SYNC sent, wire time of the release)."""
    before = st.gateway.cycles
    with st.gateway.node.lock:
        for _ in range(STALL_SYNCS):
            st.network.sync.transmit()
            time.sleep(GAP)
        last_sync = wire_now()
        time.sleep(2 * GRACE)
        released = wire_now()
    return before, last_sync, released


def test_a_stall_loses_what_the_fifo_cannot_hold_and_says_so_once(stalling) -> None:
    st = stalling
    st.sync()
    before, last_sync, released = _stall(st)
    wait_for(lambda: st.gateway.rx_fifo.lost + st.gateway.cycles - before >= STALL_SYNCS,
             "the stalled SYNCs were neither handled nor lost")
    ran = st.gateway.cycles - before
    # the one taken before the firmware stalled, then what the FIFO held
    assert ran <= 1 + RX_FIFO_DEPTH
    assert st.gateway.rx_fifo.lost == STALL_SYNCS - ran
    wait_for(lambda: any(e.code == 0x8110 for e in st.node.emcy.log), "no EMCY 0x8110")
    overruns = [e for e in st.node.emcy.log if e.code == 0x8110]
    assert len(overruns) == 1  # one per episode
    assert overruns[0].register & 0x11 == 0x11  # generic + communication error (CiA 301)
    assert struct.unpack_from("<I", overruns[0].data)[0] >= 1  # frames lost so far
    assert st.node.sdo[0x1001].raw & 0x10
    assert st.node.sdo[0x1003][1].raw == 0x8110
    # the SYNC handled after the stall latched when it was handled, after every SYNC of
    # the stall was on the wire: not at its own wire time
    latch = st.gateway.modules[0].latch_time
    assert latch is not None and latch >= st.gateway.clock.at(last_sync)
    assert latch <= st.gateway.clock.at(wire_now())
    # the next SYNC is on time again: the episode is over, bit 4 clears, error reset
    st.sync()
    wait_for(lambda: st.node.emcy.log[-1].code == 0, "no error-reset EMCY after the episode")
    assert st.node.sdo[0x1001].raw == 0
    assert sum(e.code == 0x8110 for e in st.node.emcy.log) == 1


def test_queue_backlog_answers_every_sync_latched_at_its_wire_time(stalling) -> None:
    st = stalling
    st.node.sdo[SIM_COMMAND].raw = command_word(FaultKind.QUEUE_BACKLOG, 0)
    wait_for(lambda: st.gateway.queue_backlog, "QUEUE_BACKLOG not in force")
    st.sync()
    latches: list[float] = []
    st.readers[0].read = _recording(st.readers[0].read, latches)  # type: ignore[method-assign]
    before, last_sync, _ = _stall(st)
    wait_for(lambda: st.gateway.cycles - before == STALL_SYNCS, "not every SYNC was handled")
    assert st.gateway.rx_fifo.lost == 0
    assert not any(e.code == 0x8110 for e in st.node.emcy.log)
    # each latched at its own SYNC's wire time, spread over the stall, not all at its end
    assert len(latches) == STALL_SYNCS
    assert latches == sorted(latches)
    assert latches[-1] - latches[0] >= (STALL_SYNCS - 1) * GAP * 0.9
    assert latches[-1] <= st.gateway.clock.at(last_sync)
    st.node.sdo[SIM_COMMAND].raw = command_word(FaultKind.CLEAR_ALL, 0)
    assert not st.gateway.queue_backlog


def _recording(read, into: list[float]):
    def wrapped(t: float, n_bits: int, rate: float):
        into.append(t)
        return read(t, n_bits, rate)
    return wrapped
