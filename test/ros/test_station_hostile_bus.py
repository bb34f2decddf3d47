"""A standalone ``station`` program is not made deaf by a datagram that is no CAN frame.

Before, one undecodable datagram on its group ended the station's receive
thread (python-can's CanOperationError), it answered no master any more and exited 1 on
SIGTERM. Now its receive path (``base/rx_guard.GuardedListener``) drops and counts it, logs it
at most once per second, and a master configured afterwards cycles with it. The installed
program, on a private udp_multicast group on loopback.
"""

from __future__ import annotations

import os
import socket
import struct

from ssi_bridge.base.udp_bus import derive_channel, parse_channel
from ssi_bridge.client.master import BridgeClient
from ssi_bridge.protocol.settings import BusConfig

from support.stations import ready as _ready
from support.stations import start_station as _start_station


def test_a_standalone_station_hears_a_master_after_undecodable_datagrams(tmp_path, domain_id):
    channel = derive_channel(f"deaf_{domain_id}_{os.getpid()}")
    endpoint = parse_channel(channel)
    station = _start_station(tmp_path, {"bus.interface": "udp_multicast", "bus.channel": channel})
    raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    raw.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
    raw.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, struct.pack("@I", 1))
    try:
        _ready(station)
        for _ in range(100):
            raw.sendto(b"\xc1 not a CAN frame", (endpoint.group, endpoint.port))
        client = BridgeClient(BusConfig(interface="udp_multicast", channel=channel), 1, 1)
        try:
            client.connect()  # SDO configuration: the station must still receive
            done = 0
            for _ in range(10):
                client.sync()
                done += client.wait_cycle(0.5)
            assert done >= 8
        finally:
            client.close()
    finally:
        raw.close()
        station.terminate()
    assert station.wait(10) == 0
    err = station.stderr.read().decode()
    assert "Traceback" not in err, err[-3000:]
    assert 1 <= err.count("not a CAN frame") <= 2, err[-3000:]
