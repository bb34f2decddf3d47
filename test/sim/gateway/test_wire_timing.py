"""The simulated CAN wire: frame lengths (ISO 11898-1 base frames with stuff bits), SYNC ->
last TPDO timing against the formula, the rate table in docs/canopen.md, and the latch time
taken from the SYNC frame's own timestamp."""

from __future__ import annotations

import itertools
import random
import time
from pathlib import Path

import can
import pytest

from ssi_bridge.protocol import wire
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
from ssi_bridge.sim.gateway.bus import open_bus
from ssi_bridge.sim.gateway.gateway import XnGateway
from ssi_bridge.base.timebase import ModelClock
from ssi_bridge.client.master import BridgeClient
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi
from support.virtual_bus import ScriptedReader

REPO = Path(__file__).resolve().parents[3]
_ch = itertools.count()


def test_fast_frame_length_equals_the_bit_by_bit_reference():
    rng = random.Random(7)
    for _ in range(3000):
        cid = rng.randrange(0x800)
        data = bytes(rng.choice((0, 0xFF, rng.randrange(256))) for _ in range(rng.randrange(9)))
        assert wire.frame_bits(cid, data) == wire.reference_frame_bits(cid, data)
        assert wire.frame_bits(cid, data) <= wire.worst_frame_bits(len(data))


def test_a_remembered_frame_length_follows_the_frame_content():
    # frame_bits remembers lengths by content: the same bytearray changed in place (as a
    # received payload buffer may be) is a new frame
    data = bytearray(8)
    zeros = wire.frame_bits(0x181, data)
    data[:] = bytes([0x55] * 8)
    assert wire.frame_bits(0x181, data) == wire.reference_frame_bits(0x181, bytes(data)) != zeros
    data[:] = bytes(8)
    assert wire.frame_bits(0x181, data) == zeros == wire.reference_frame_bits(0x181, bytes(8))
    with pytest.raises(ValueError, match="11-bit"):
        wire.frame_bits(0x800, data)
    with pytest.raises(ValueError, match="11-bit"):  # a refusal is not remembered as a length
        wire.frame_bits(0x800, data)


def test_frame_length_counts_stuff_bits():
    # 34 + 8n stuffable bits + 13 tail bits, plus stuffing: all-zero data stuffs every 5 bits
    assert wire.frame_bits(0x080) >= 47
    assert wire.frame_bits(0x181, bytes(8)) > wire.frame_bits(0x181, bytes([0x55] * 8))
    assert wire.stuff_count([0] * 5) == 1 and wire.stuff_count([0] * 10) == 2
    assert wire.stuff_count([1, 0] * 10) == 0


def test_docs_rate_table_is_the_formula():
    text = (REPO / "docs" / "canopen.md").read_text()
    assert wire.rate_table() in text


@pytest.mark.parametrize("bitrate", [125_000, 1_000_000])
def test_sync_to_last_tpdo_takes_the_wire_time_of_the_formula(bitrate):
    channel = f"wire-{next(_ch)}"
    config = BusConfig(channel=channel, node_id=3, bitrate=bitrate)
    gateway = XnGateway(config, 3, [Xn1Ssi(ScriptedReader(0x1234 + i), slot=i + 1)
                                    for i in range(2)])
    client = BridgeClient(config, 3, 2, sdo_timeout=1.0, opener=wire_bus)
    sniffer = open_bus(config)
    gateway.start()
    try:
        client.connect()
        # drain what connecting left queued; the station's heartbeat (0x1017, 50 ms) keeps
        # the bus from ever being quiet for 50 ms, so the wait is well below that period
        while sniffer.recv(0.01) is not None:
            pass
        spans, expected = [], []
        for _ in range(20):
            client.sync()
            assert client.wait_cycle(1.0)
            frames = []
            deadline = time.monotonic() + 1.0
            while len(frames) < 4 and time.monotonic() < deadline:
                msg = sniffer.recv(0.1)
                if msg is not None and (msg.arbitration_id == 0x80 or
                                        0x180 < msg.arbitration_id < 0x500):
                    frames.append(msg)
            assert frames[0].arbitration_id == 0x80, frames
            sync, first, last = frames[0], frames[1], frames[-1]
            lengths = [wire.frame_bits(m.arbitration_id, m.data) / bitrate for m in frames]
            # SYNC -> last TPDO is never shorter than the frames on the wire
            assert last.timestamp - sync.timestamp >= sum(lengths[1:]) * 0.999
            # the station answers after its reaction time; from there its TPDOs are back to
            # back on the wire, each as long as the formula says: first end -> last end
            spans.append(last.timestamp - first.timestamp)
            expected.append(sum(lengths[2:]))
            time.sleep(0.01)
        for got, want in zip(spans, expected):
            assert got == pytest.approx(want, rel=0.10), (spans, expected)
    finally:
        sniffer.shutdown()
        client.close()
        gateway.stop()


def test_latch_is_the_sync_frames_time_however_late_the_thread_runs():
    # the gateway used to read its clock and time.time() in two statements; a thread switch
    # between them moved the latch back by the switch (5 ms GIL interval), into the previous
    # burst. Now the latch is the frame's timestamp in the model clock: one subtraction.
    clock = ModelClock(epoch=1000.0)
    gateway = XnGateway(BusConfig(channel=f"latch-{next(_ch)}"), 1, [Xn1Ssi(None, slot=1)],
                        clock=clock)
    assert gateway._acquisition_time(1000.25) == pytest.approx(0.25, abs=1e-9)
    time.sleep(0.01)  # the thread runs late: the latch does not move
    assert gateway._acquisition_time(1000.25) == pytest.approx(0.25, abs=1e-9)


def test_udp_multicast_frames_arrive_after_their_wire_time_in_the_same_time_base():
    # between processes (or hosts) a frame carries the receiver's kernel receive time, in the
    # same CLOCK_REALTIME base as the sender's wire time: it is never before the frame's end
    import os
    import socket

    channel = "239.74.163.2"
    port = 43000 + os.getpid() % 2000
    config = BusConfig(interface="udp_multicast", channel=channel, bitrate=125_000)
    try:
        a = can.Bus(interface="udp_multicast", channel=channel, port=port)
        b = can.Bus(interface="udp_multicast", channel=channel, port=port)
    except (OSError, can.CanError, ImportError) as err:
        pytest.skip(f"no multicast on this host: {err}")
    from ssi_bridge.sim.gateway.bus import Wire, WireBus

    sender, receiver = WireBus(a, Wire(config.bitrate)), WireBus(b, Wire(config.bitrate))
    try:
        msg = can.Message(arbitration_id=0x181, data=bytes(range(8)), is_extended_id=False)
        sender.send(msg)
        end = msg.timestamp
        got = None
        deadline = time.monotonic() + 5.0
        while got is None and time.monotonic() < deadline:
            got = receiver.recv(0.5)
            if got is not None and got.arbitration_id != 0x181:
                got = None
        assert got is not None, "frame not received over udp_multicast"
        assert got.timestamp >= end - 1e-6  # arrived after its last bit was on the wire
        assert bytes(got.data) == bytes(range(8))
        assert receiver.wire.busy_until >= got.timestamp  # the receiver learnt the wire's use
    except socket.error as err:  # pragma: no cover - host without multicast routing
        pytest.skip(f"no multicast on this host: {err}")
    finally:
        sender.shutdown()
        receiver.shutdown()
