"""A SYNC between processes latches at its wire time, not at its (late) arrival.

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


def test_a_late_stations_tpdos_answer_on_the_syncs_wire_time_line(channel: str) -> None:
    # CiA 301: synchronous TPDOs go out inside their SYNC's cycle. A station that gets to the
    # SYNC late (a starved process) still puts them right after that SYNC on the wire, so a
    # master counts them for it, not for a newer SYNC sent meanwhile (client/samples.py)
    from ssi_bridge.client.master import BridgeClient
    from ssi_bridge.protocol.wire import frame_bits

    settings = station_settings({"joints": ["j"], "j.slot": 1,
                                 "bus.interface": "udp_multicast", "bus.channel": channel})
    station = Station(settings)
    station.start()
    client = BridgeClient(BusConfig(interface="udp_multicast", channel=channel), 1, 1, opener=wire_bus)
    master = open_udp_bus(channel)
    try:
        client.connect()  # OPERATIONAL, TPDO1 (image) and TPDO9 (positions) on SYNC
        # the station's heartbeat thread goes on sending (at its own "now"), also between the
        # SYNC's end and the moment the station gets to the SYNC
        client.write_object(0x1017, 0, 5)
        client.close()
        time.sleep(3 * LATE)
        sync_wire = wire_now() - LATE
        master.send(can.Message(arbitration_id=0x080, is_extended_id=False,
                                timestamp=sync_wire))
        got = [_recv(master, 0x181), _recv(master, 0x1E1)]
        ends = sorted(frame_wire_time(m) for m in got)
        # back to back from the SYNC's end: each frame its own length at the bit rate
        first_len = min(frame_bits(m.arbitration_id, m.data) for m in got) / 500_000
        assert ends[0] >= sync_wire + first_len - 1e-9
        assert ends[-1] - sync_wire < 0.002  # not LATE after it, where the thread ran
    finally:
        master.shutdown()
        client.close()
        station.stop()


def test_an_answer_goes_in_the_first_gap_after_its_sync() -> None:
    # a heartbeat this process put on the wire 5 ms after the SYNC, before the station got
    # to the SYNC: the answer fits in before it; where it does not fit, it goes after it
    from ssi_bridge.sim.gateway.bus import Wire
    from ssi_bridge.protocol.wire import frame_bits

    wire = Wire(500_000)
    sync_end = 100.0
    wire.observe(sync_end, sync=True, length=frame_bits(0x080, b"") / 500_000)
    hb_end = wire.claim(frame_bits(0x701, b"\x05"), sync_end + 0.005)
    tpdo = can.Message(arbitration_id=0x181, data=bytes(8), is_extended_id=False)
    assert wire.claim_all([tpdo], sync_end, answering=sync_end)
    assert tpdo.timestamp == pytest.approx(sync_end + frame_bits(0x181, bytes(8)) / 500_000)
    assert wire.busy_until == hb_end  # the wire's end is still the heartbeat's
    # a gap too short for a burst of 100 frames: it goes after the heartbeat
    burst = [can.Message(arbitration_id=0x181, data=bytes(8), is_extended_id=False)
             for _ in range(100)]
    assert wire.claim_all(burst, sync_end, answering=sync_end)
    assert burst[0].timestamp > hb_end
    # a newer SYNC on the wire: no answer to the older one (CiA 301 synchronous window)
    wire.observe(hb_end + 0.5, sync=True)
    assert not wire.claim_all([tpdo], sync_end, answering=sync_end)
