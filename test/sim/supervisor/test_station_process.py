"""The ``station`` program on its own (sim/supervisor/station.py): its stop signals and its
receive path, as a process on a private udp_multicast group on loopback.

No node and no DDS domain: the station is rclpy-free, and a station given a udp_multicast
``bus.channel`` uses that channel as it is (``with_station_bus``), so a channel derived from
this process and the test's own name keeps parallel runs apart (the tests were node-process
tests before only because they took a ROS domain id for that name).
"""

from __future__ import annotations

import os
import signal
import socket
import struct
import time

from ssi_bridge.base.udp_bus import derive_channel, parse_channel
from ssi_bridge.client.master import BridgeClient
from ssi_bridge.protocol.settings import BusConfig

from support.stations import ready as _ready
from support.stations import start_station as _start_station


def _channel(name: str) -> str:
    """A udp_multicast channel no other test run uses."""
    return derive_channel(f"{name}-{os.getpid()}-{time.monotonic_ns()}")


def test_station_sigterm_is_a_clean_exit(tmp_path):
    station = _start_station(tmp_path, {"bus.interface": "udp_multicast",
                                        "bus.channel": _channel("sigterm")})
    try:
        _ready(station)
    finally:
        station.terminate()
    assert station.wait(10) == 0


def test_station_survives_a_storm_of_stop_signals(tmp_path):
    """Any number of SIGINT/SIGTERM at any moment: exit 0. A node's stop, its death
    (PR_SET_PDEATHSIG) and a terminal's Ctrl-C can all reach the station at once; a handler
    that takes a lock (threading.Event.set) deadlocks when a second signal lands inside the
    first one's set, and the station then outlives its node (seen as an orphan)."""
    for run in range(6):
        station = _start_station(tmp_path, {"bus.interface": "udp_multicast",
                                            "bus.channel": _channel(f"storm-{run}")})
        try:
            _ready(station)
            for k in range(400):
                station.send_signal(signal.SIGTERM if k % 2 else signal.SIGINT)
            code = station.wait(20)
        finally:
            if station.poll() is None:
                station.kill()
                station.wait()
        assert code == 0, station.stderr.read().decode()[-2000:]


def test_a_standalone_station_hears_a_master_after_undecodable_datagrams(tmp_path):
    """A standalone ``station`` program is not made deaf by a datagram that is no CAN frame.

    Before, one undecodable datagram on its group ended the station's receive thread
    (python-can's CanOperationError), it answered no master any more and exited 1 on SIGTERM.
    Now its receive path (``base/rx_guard.GuardedListener``) drops and counts it, logs it at
    most once per second, and a master configured afterwards cycles with it."""
    channel = _channel("deaf")
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
