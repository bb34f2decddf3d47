"""A TPDO is counted for the SYNC it followed on the wire, however late it arrives.

A station sends a SYNC's synchronous TPDOs inside that SYNC's cycle (CiA 301 synchronous
window), so on the wire they lie between their SYNC and the next one. Between processes
(udp_multicast) a frame arrives when its sender got to send it: under CPU load after the
master's next SYNC. The master matches it by its wire time (``base/timebase``
``frame_wire_time``, the sender's end of frame the datagram carries), not by its arrival:
the sample keeps its own SYNC's stamp and the newer cycle stays incomplete (docs/node.md
"Which cycle a TPDO answers"). Real sockets on loopback, a real station for the
configuration; the late frames are sent by hand with the wire time they would have had.
"""

from __future__ import annotations

import os
import time

import can
import pytest

from ssi_bridge.client.master import BridgeClient
from ssi_bridge.client.receive import FrameListener
from ssi_bridge.client.samples import ClientCounters
from ssi_bridge.client.sdo import position_pdos
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
from ssi_bridge.protocol.dictionary import tpdo_cob_base
from ssi_bridge.base.udp_bus import UdpFrame, derive_channel, open_udp_bus
from ssi_bridge.protocol.settings import station_settings
from ssi_bridge.sim.gateway.station import Station

NODE = 1


def test_the_listener_hands_the_network_the_wire_time_of_a_frame() -> None:
    import canopen

    seen: list[float] = []
    network = canopen.Network()  # not connected: the listener only dispatches to subscribers
    network.subscribe(0x181, lambda can_id, data, t: seen.append(t))
    sent = can.Message(arbitration_id=0x181, is_extended_id=False, data=bytes(8), timestamp=5.0)
    listener = FrameListener(network, ClientCounters())
    listener(UdpFrame.of(sent, timestamp=5.004, wire_time=5.0))  # arrived 4 ms late
    listener(can.Message(arbitration_id=0x181, is_extended_id=False, timestamp=6.0))
    assert seen == [5.0, 6.0]


def test_a_tpdo_arriving_after_the_next_sync_counts_for_its_own(
        request: pytest.FixtureRequest) -> None:
    channel = derive_channel(f"attr-{os.getpid()}-{request.node.name}")
    station = Station(station_settings({"joints": ["j"], "j.slot": 1,
                                        "bus.interface": "udp_multicast",
                                        "bus.channel": channel}))
    station.start()
    client = BridgeClient(BusConfig(interface="udp_multicast", channel=channel), NODE, 1, opener=wire_bus)
    late_sender = open_udp_bus(channel)  # a plain bus: frames go out as stamped
    try:
        client.connect()
        client.sync()
        assert client.wait_cycle(2.0)
        station.gateway.silent = True  # the answers below come by hand
        first = client.sync()
        # a SYNC sent at once would queue behind the first on the wire and end one SYNC frame
        # (0.19 ms) after it, before the answers' wire time below: give the first its cycle
        time.sleep(0.001)
        second = client.sync()
        assert second > first + 0.0002
        # the station's answers to the first SYNC: on the wire right after it (its wire
        # time), handed to the socket only now, after the second SYNC
        image = bytes([1, 2, 3, 4, 0, 0, 0, 0])
        (pdo, _slots), = position_pdos(1)
        for can_id, data in ((tpdo_cob_base(1) + NODE, image),
                             (tpdo_cob_base(pdo) + NODE, (1234).to_bytes(4, "little"))):
            late_sender.send(can.Message(arbitration_id=can_id, data=data,
                                         is_extended_id=False, timestamp=first + 0.0002))
        deadline = time.monotonic() + 5.0
        while client.table.late_frames < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert client.table.late_frames == 2  # answers to an older SYNC than the current one
        assert not client.table.cycle_complete()  # the second SYNC got no answer
        sample = client.latest(1)
        assert sample is not None and sample.position == 1234
        assert sample.sync_time == first  # stamped with the SYNC it answered
    finally:
        late_sender.shutdown()
        client.close()
        station.stop()
