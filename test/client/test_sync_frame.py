"""The master's SYNC, cycle after cycle: the same frame on the wire, its own wire time each.

CiA 301 §7.2.5: the SYNC (COB-ID 0x080) of a producer without a counter carries no data. The
master sends that frame every cycle: on a bus that leaves what it sent unstamped
(udp_multicast) the same frame again, on a simulated wire (which stamps each frame with its
end on the wire) a new one each time, whose stamp is that SYNC's wire time (base/timebase.py).
"""

from __future__ import annotations

import os

import pytest

from ssi_bridge.base.udp_bus import UdpCanBus, derive_channel
from ssi_bridge.client.bus_master import CanMaster
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.protocol.wire import frame_bits
from ssi_bridge.sim.gateway.bus import open_bus as wire_bus


def test_every_sync_on_udp_is_the_empty_sync_frame_and_counts_on_the_load(
        request: pytest.FixtureRequest) -> None:
    channel = derive_channel(f"sync-{os.getpid()}-{request.node.name}")
    listener = UdpCanBus(channel)
    master = CanMaster(BusConfig(interface="udp_multicast", channel=channel,
                                 bitrate=1_000_000))
    try:
        master.connect()
        times = [master.sync() for _ in range(3)]
        frames = [listener.recv(2.0) for _ in range(3)]
        figures = master.load.figures()
    finally:
        master.close()
        listener.shutdown()
    assert times == sorted(times) and len(set(times)) == 3
    for frame in frames:
        assert frame is not None
        assert (frame.arbitration_id, bytes(frame.data), frame.dlc) == (0x080, b"", 0)
        assert not (frame.is_remote_frame or frame.is_extended_id)
    # three SYNCs alone on the wire: one frame a cycle, the SYNC's bits at 1 Mbit/s
    assert figures["frames_per_cycle"] == "1.00"
    assert figures["wire_ms_per_cycle"] == f"{frame_bits(0x080) / 1e3:.3f}"


def test_on_a_stamping_wire_each_sync_has_its_own_frame_and_time(station, channel: str
                                                                 ) -> None:
    _gateway, client, _readers = station
    sniffer = wire_bus(BusConfig(channel=channel))
    try:
        times = [client.sync() for _ in range(3)]
        seen = []
        while len(seen) < 3 and (msg := sniffer.recv(2.0)) is not None:
            if msg.arbitration_id == 0x080:
                seen.append(msg)
    finally:
        sniffer.shutdown()
    # each SYNC's wire time is its own frame's end on the wire, as every receiver sees it
    assert times == [m.timestamp for m in seen]
    assert times == sorted(times) and len(set(times)) == 3
