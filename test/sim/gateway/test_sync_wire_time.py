"""A SYNC between processes latches at its wire time, not at its (late) arrival; answers are
stamped when really sent.

On udp_multicast a frame reaches the other process when its sender's thread gets to send it:
the sender stamps the frame's end on the simulated wire, sleeps until then and sends, and
under CPU load it wakes milliseconds late. The datagram carries that stamp
(``base/udp_bus.py``); ``frame_wire_time`` gives it back, and the station latches its
modules on it. 000 §"Process data": the XN-1SSI acquires the encoder value on the SYNC, so
REG_SSI_POS is the shaft position at the SYNC's instant on the wire, wherever the station runs.
Real sockets on loopback, a real station; the ground truth is the same module model cycled at
the SYNC's wire time directly.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator

import can
import pytest

from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
from ssi_bridge.sim.gateway.bus import open_bus
from ssi_bridge.base.udp_bus import (
    WIRE_TIME_PLAUSIBLE, UdpFrame, derive_channel, open_udp_bus,
)
from ssi_bridge.protocol.settings import station_settings
from ssi_bridge.sim.gateway.station import SimStation, Station
from ssi_bridge.base.timebase import frame_wire_time, wire_now

#: how late the simulated sender put its SYNC out after the SYNC's end on the wire (s)
LATE = 0.030
#: shaft speed (rev/s): LATE is then 0.06 rev, hundreds of encoder steps
VELOCITY = 2.0


@pytest.fixture
def channel(request: pytest.FixtureRequest) -> str:
    """A udp_multicast channel of this test alone."""
    return derive_channel(f"wt-{os.getpid()}-{request.node.name}")


@pytest.fixture
def pair(channel: str) -> Iterator[tuple[can.BusABC, can.BusABC]]:
    cfg = BusConfig(interface="udp_multicast", channel=channel)
    a, b = open_bus(cfg), open_bus(cfg)
    yield a, b
    a.shutdown()
    b.shutdown()


def _recv(bus: can.BusABC, can_id: int, timeout: float = 5.0) -> can.Message:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        msg = bus.recv(0.5)
        if msg is not None and msg.arbitration_id == can_id:
            return msg
    raise AssertionError(f"no frame 0x{can_id:03X} within {timeout} s")


def test_the_senders_end_of_frame_survives_the_datagram(pair) -> None:
    sender, receiver = pair
    msg = can.Message(arbitration_id=0x181, data=bytes(range(8)), is_extended_id=False)
    sender.send(msg)  # the wire stamps its end of frame, then sends
    got = _recv(receiver, 0x181)
    assert isinstance(got, UdpFrame)
    assert frame_wire_time(got) == msg.timestamp  # exactly: a double in the datagram
    assert got.timestamp >= msg.timestamp  # the kernel's receive time, after the frame's end
    assert bytes(got.data) == bytes(range(8))


def test_a_frame_sent_late_keeps_its_wire_time(channel: str) -> None:
    sender, receiver = open_udp_bus(channel), open_udp_bus(channel)
    try:
        stamped = wire_now() - LATE  # its end on the wire; the sender woke LATE after it
        sender.send(can.Message(arbitration_id=0x080, is_extended_id=False,
                                timestamp=stamped))
        got = _recv(receiver, 0x080)
        assert frame_wire_time(got) == stamped
        assert got.timestamp - stamped >= LATE  # the receive time is as late as the send
    finally:
        sender.shutdown()
        receiver.shutdown()


@pytest.mark.parametrize("age", [None, 10 * WIRE_TIME_PLAUSIBLE])
def test_a_frame_without_a_plausible_stamp_is_on_the_wire_when_received(channel: str,
                                                                        age: float | None) -> None:
    # a python-can tool sends unstamped frames (0.0) or replays logged ones with old stamps
    sender, receiver = open_udp_bus(channel), open_udp_bus(channel)
    try:
        stamp = 0.0 if age is None else wire_now() - age
        sender.send(can.Message(arbitration_id=0x701, data=b"\x05", is_extended_id=False,
                                timestamp=stamp))
        got = _recv(receiver, 0x701)
        assert frame_wire_time(got) == got.timestamp
    finally:
        sender.shutdown()
        receiver.shutdown()


def test_virtual_frames_are_on_the_wire_at_their_timestamp() -> None:
    msg = can.Message(arbitration_id=0x080, is_extended_id=False, timestamp=1234.5)
    assert frame_wire_time(msg) == 1234.5


def test_a_station_latches_on_the_syncs_wire_time_not_on_its_late_arrival(channel: str) -> None:
    values = {"joints": ["j"], "j.slot": 1, "j.motion.velocity": VELOCITY,
              "bus.interface": "udp_multicast", "bus.channel": channel}
    settings = station_settings(values)
    station = Station(settings)
    master = open_udp_bus(channel)  # a plain python-can bus: the frame goes out as stamped
    station.start()
    try:
        assert station.gateway.nmt_state == "PRE-OPERATIONAL"  # a SYNC cycles the modules
        sync_wire = wire_now() - LATE
        master.send(can.Message(arbitration_id=0x080, is_extended_id=False,
                                timestamp=sync_wire))
        deadline = time.monotonic() + 5.0
        while station.gateway.cycles < 1 and time.monotonic() < deadline:
            time.sleep(0.005)
        assert station.gateway.cycles == 1
        module = station.sim.modules[0]
        # ground truth: the same encoder, line and module, cycled at the SYNC's wire time
        truth = SimStation(settings.joints).modules[0]
        truth.cycle(station.model_clock.at(sync_wire))
        assert module.latch_time == pytest.approx(truth.latch_time, abs=1e-9)
        assert module.ssi_pos == truth.ssi_pos  # REG_SSI_POS of the shaft at the SYNC
    finally:
        master.shutdown()
        station.stop()


def test_a_late_syncs_answer_is_stamped_when_it_is_really_sent(channel: str) -> None:
    # The SYNC's datagram goes out LATE after its end on the wire (its sender woke late). The
    # station hears it only then: it latches at the SYNC's wire time (its own thread was on
    # time, docs/canopen.md "Stalls"), and its TPDOs go on the wire when they are really sent,
    # never at a wire time before that: a receiver that has seen the wire up to some instant
    # never gets a frame claiming an earlier one (a CAN frame is on the wire when it is sent)
    from ssi_bridge.client.master import BridgeClient

    settings = station_settings({"joints": ["j"], "j.slot": 1,
                                 "bus.interface": "udp_multicast", "bus.channel": channel})
    station = Station(settings)
    station.start()
    client = BridgeClient(BusConfig(interface="udp_multicast", channel=channel), 1, 1,
                          opener=wire_bus)
    master = open_udp_bus(channel)
    try:
        client.connect()  # OPERATIONAL, TPDO1 (image) and TPDO9 (positions) on SYNC
        client.close()
        time.sleep(3 * LATE)
        sync_wire = wire_now() - LATE
        sent = wire_now()  # the datagram leaves now
        master.send(can.Message(arbitration_id=0x080, is_extended_id=False,
                                timestamp=sync_wire))
        got = [_recv(master, 0x181), _recv(master, 0x1E1)]
        assert min(frame_wire_time(m) for m in got) > sent
        module = station.sim.modules[0]
        assert module.latch_time == pytest.approx(station.model_clock.at(sync_wire), abs=1e-9)
    finally:
        master.shutdown()
        client.close()
        station.stop()


def test_an_answer_goes_on_the_wire_when_it_is_ready_never_before() -> None:
    # a heartbeat this process put on the wire 5 ms after the SYNC, before the station got
    # to the SYNC: the answer goes after it, at its own ready time, not in a gap before it
    from ssi_bridge.sim.gateway.bus import Wire
    from ssi_bridge.protocol.wire import frame_bits

    wire = Wire(500_000)
    sync_end = 100.0
    wire.observe(sync_end, sync=True)
    hb_end = wire.claim(frame_bits(0x701, b"\x05"), sync_end + 0.005)
    tpdo = can.Message(arbitration_id=0x181, data=bytes(8), is_extended_id=False)
    length = frame_bits(0x181, bytes(8)) / 500_000
    assert wire.claim_all([tpdo], sync_end + 0.001, answering=sync_end)
    assert tpdo.timestamp == pytest.approx(hb_end + length)  # behind the heartbeat
    ready = hb_end + 0.010
    late = can.Message(arbitration_id=0x181, data=bytes(8), is_extended_id=False)
    assert wire.claim_all([late], ready, answering=sync_end)
    assert late.timestamp == pytest.approx(ready + length)  # at its ready time, not earlier
    # a newer SYNC on the wire: no answer to the older one (CiA 301 synchronous window)
    wire.observe(ready + 0.5, sync=True)
    assert not wire.claim_all([tpdo], ready + 0.6, answering=sync_end)


def test_syncs_faster_than_the_ssi_reads_are_answered_after_their_reads_never_before(
        channel: str) -> None:
    # Another producer's SYNCs in a burst (a starved sender catching up on its rate): the
    # gateway handles them back to back, each latch after the previous cycle's SSI reads and
    # their rest (gateway.SSI_REST_S), so the latches fall behind the SYNCs. An answer carries
    # its cycle's REG_SSI_POS: it goes on the wire after that read, so no position on the wire
    # is the shaft's at an instant after the frame's own wire time (a master holds a sample
    # to the window between its SYNC and its first frame, docs/node.md "Which cycle a TPDO
    # answers"). Before the fix a burst of 40 put positions 3-7 ms ahead on the wire.
    from ssi_bridge.client.master import BridgeClient
    from support.truth import TruthOracle

    values = {"joints": ["j"], "j.slot": 1, "j.motion.velocity": VELOCITY,
              "bus.interface": "udp_multicast", "bus.channel": channel}
    station = Station(station_settings(values))
    station.start()
    client = BridgeClient(BusConfig(interface="udp_multicast", channel=channel), 1, 1,
                          opener=wire_bus)
    master = open_udp_bus(channel)
    try:
        client.connect()  # OPERATIONAL, TPDO1 (image) and TPDO9 (positions) on SYNC
        client.close()
        oracle = TruthOracle.from_params(values, station.model_clock.epoch)
        for _ in range(40):  # unstamped: on the wire when received, back to back
            master.send(can.Message(arbitration_id=0x080, is_extended_id=False))
        positions = []
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline:
            msg = master.recv(0.1)
            if msg is not None and msg.arbitration_id == 0x1E1:
                positions.append((frame_wire_time(msg), int.from_bytes(msg.data[:4], "little",
                                                                        signed=True)))
        assert positions, "the burst was answered"
        scale = oracle.joints["j"].scale
        ahead = [(t, oracle.residual("j", t, scale.position(counts)))
                 for t, counts in positions]
        # residual > 0: the position the shaft reaches after the frame's wire time
        assert max(r for _, r in ahead) <= 1.0, [f"{r:+.0f}" for _, r in ahead]
    finally:
        master.shutdown()
        client.close()
        station.stop()
