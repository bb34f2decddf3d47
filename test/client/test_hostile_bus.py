"""Nothing a foreign node puts on the bus stops the master's or the station's receive path.

Hostile traffic comes from sockets and buses of the test, on
loopback only: raw UDP datagrams that are not python-can CAN frames (to the group, and
unicast to the port), a msgpack frame with identifier 0xFFFF and DLC 15 (no CAN 2.0A frame:
11-bit identifiers, DLC 0..8, CiA 301 §7.2 / ISO 11898-1), and a receive error of the bus
itself. The master is a real :class:`BridgeClient` (canopen network, python-can notifier) and
the station a real simulated XN-GW-CANOPEN; after the hostile traffic both still cycle.
"""

from __future__ import annotations

import logging
import os
import socket
import struct
import time

import can
import pytest
from can.interfaces.udp_multicast.utils import pack_message
from can.interfaces.virtual import VirtualBus

from ssi_bridge.base.udp_bus import derive_channel, open_udp_bus, parse_channel
from ssi_bridge.client.master import BridgeClient
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
from ssi_bridge.sim.gateway.gateway import XnGateway
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

from support.virtual_bus import ScriptedReader

from .conftest import run_cycles

NODE = 1
#: a datagram that is no msgpack at all, and one that is msgpack but no CAN frame
GARBAGE = b"\xc1 this is not a CAN frame"
#: python-can's wire format with an identifier and DLC no CAN 2.0A frame can carry
BAD_FRAME = pack_message(can.Message(arbitration_id=0xFFFF, is_extended_id=False, dlc=15,
                                    data=bytes(15)))  # unchecked: no CAN 2.0A frame


def _raw_sender() -> socket.socket:
    """A plain UDP socket sending from loopback (multicast on loopback only)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
    sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, struct.pack("@I", 1))
    return sock


def test_datagrams_that_are_no_can_frames_stop_neither_master_nor_station(
        udp_station, caplog: pytest.LogCaptureFixture) -> None:
    """Undecodable datagrams to the group: counted (``undecodable_frames``), logged at most
    once per second per receiver, and SYNC, TPDOs and the station go on. Before: python-can's
    CanOperationError ended the notifier thread, every later send raised it, and the
    station went deaf."""
    channel, station, client = udp_station
    endpoint = parse_channel(channel)
    assert run_cycles(client, 5) >= 4
    sender = _raw_sender()
    caplog.set_level(logging.WARNING)
    try:
        for i in range(100):
            sender.sendto(GARBAGE if i % 2 else BAD_FRAME, (endpoint.group, endpoint.port))
        time.sleep(0.3)
        assert run_cycles(client, 20) >= 18, "the master must still SYNC and receive TPDOs"
    finally:
        sender.close()
    assert client.counters.undecodable_frames == 100
    assert client.gateway_alive
    sample = client.latest(1)
    assert sample is not None and sample.sync_time > 0
    dropped = [r for r in caplog.records if "not a CAN frame" in r.getMessage()]
    # one line per receiver (master, station) within the second the burst took
    assert 1 <= len(dropped) <= 4, [r.getMessage() for r in dropped]
    assert not any(r.exc_info for r in caplog.records), "no traceback in the log"


def test_a_datagram_unicast_to_the_port_is_not_heard() -> None:
    """The bus is bound to its group (docs/canopen.md "CAN over UDP"): a valid python-can
    frame unicast to 127.0.0.1:<port> is not a frame on the bus; the same frame sent to the
    group is. Before: the socket was bound to 0.0.0.0:<port> and took it (an NMT reset sent
    that way was executed)."""
    channel = derive_channel(f"unicast-{os.getpid()}")
    endpoint = parse_channel(channel)
    bus = open_udp_bus(channel)
    sender = _raw_sender()
    nmt_reset = pack_message(can.Message(arbitration_id=0x000, data=[0x81, 0x01],
                                         is_extended_id=False))
    try:
        sender.sendto(nmt_reset, ("127.0.0.1", endpoint.port))
        assert bus.recv(0.3) is None, "a unicast datagram reached the CAN bus"
        sender.sendto(nmt_reset, (endpoint.group, endpoint.port))
        heard = bus.recv(1.0)
        assert heard is not None and heard.arbitration_id == 0 and bytes(heard.data) == b"\x81\x01"
    finally:
        sender.close()
        bus.shutdown()


def test_a_socket_on_the_port_of_one_address_does_not_block_the_bus() -> None:
    """Bound to GROUP:PORT, the bus shares its port with a socket on 127.0.0.1:<port> that
    has no SO_REUSEADDR (a DDS or client socket that happened to get it)."""
    holder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    holder.bind(("127.0.0.1", 0))
    port = holder.getsockname()[1]
    try:
        bus = open_udp_bus(f"239.74.251.7:{port}@127.0.0.1")
        bus.shutdown()
    finally:
        holder.close()


class UnpluggableBus(VirtualBus):
    """python-can's virtual bus whose receive fails like an interface gone down (ENETDOWN)
    while :attr:`unplugged` is set: what socketcan raises after ``ip link set can0 down``."""

    unplugged = False

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self.unplugged:
            time.sleep(0.001)
            raise can.CanOperationError("Error receiving: [Errno 100] Network is down")
        return super()._recv_internal(timeout)


def test_a_receive_error_is_counted_and_the_master_receives_again(channel: str) -> None:
    """A receive error of the bus (the interface went down for 0.2 s): counted as
    ``receive_errors``, and once the interface is back SYNC and TPDOs flow again without a
    reconnect. Before: the notifier thread ended and every send raised the error."""
    gateway = XnGateway(BusConfig(channel=channel, node_id=5), 5,
                        [Xn1Ssi(ScriptedReader(77), slot=1)])
    master_bus = UnpluggableBus(channel=channel, preserve_timestamps=True)
    client = BridgeClient(master_bus, 5, 1, sdo_timeout=0.3, handshake_timeout=0.5)
    gateway.start()
    try:
        client.connect()
        assert run_cycles(client, 5) >= 4
        master_bus.unplugged = True
        time.sleep(0.2)
        master_bus.unplugged = False
        assert client.counters.receive_errors > 0
        # a receive step that saw the interface down just before it came back may still
        # raise once: the count settles with the first cycles after the return
        run_cycles(client, 3)
        errors = client.counters.receive_errors
        assert run_cycles(client, 10) >= 8, "the master must receive again"
        assert client.counters.receive_errors == errors
        sample = client.latest(1)
        assert sample is not None and sample.position == 77
    finally:
        client.close()
        gateway.stop()


def test_a_subscriber_that_raises_stops_neither_the_others_nor_the_receive_path(
        channel: str) -> None:
    """Two subscribers on one COB-ID, the first raises (a malformed frame it cannot parse):
    the second still gets the frame, the next frame is received, and the fault is counted
    once per frame as ``callback_errors``. Before: canopen's ``Network.notify`` stopped at
    the first subscriber that raised."""
    import canopen

    from ssi_bridge.base.rx_guard import CALLBACK_ERROR, GuardedListener

    network = canopen.Network()
    listener = GuardedListener(network, "test")
    network.listeners[:] = [listener]
    seen: list[bytes] = []

    def breaks(can_id: int, data: bytearray, t: float) -> None:
        raise ValueError("cannot parse")

    network.subscribe(0x185, breaks)
    network.subscribe(0x185, lambda can_id, data, t: seen.append(bytes(data)))
    network.connect(interface="virtual", channel=channel)
    sender = can.Bus(interface="virtual", channel=channel)
    try:
        for payload in (b"\x01", b"\x02"):
            sender.send(can.Message(arbitration_id=0x185, data=payload, is_extended_id=False))
        deadline = time.monotonic() + 2.0
        while len(seen) < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        sender.shutdown()
        network.disconnect()
    assert seen == [b"\x01", b"\x02"]
    assert listener.faults[CALLBACK_ERROR] == 2


def test_the_listen_only_observer_and_the_can_log_survive_undecodable_datagrams(
        tmp_path, request: pytest.FixtureRequest) -> None:
    """The other two receive paths on a udp_multicast bus: the listen-only observer
    (``client/listener.py``) and the CAN log (``client/sniffer.py``) count the datagrams by
    kind and still take the next frame. Before: the first one ended their notifier thread
    (the sniffer had no ``on_error``; the observer logged every one)."""
    from ssi_bridge.client.listener import ListenOnlyClient
    from ssi_bridge.client.sniffer import CanSniffer

    channel = derive_channel(f"observers-{os.getpid()}-{request.node.name}")
    endpoint = parse_channel(channel)
    config = BusConfig(interface="udp_multicast", channel=channel)
    observer = ListenOnlyClient(config, NODE, 1)
    observer.connect()
    sniffer = CanSniffer(config, tmp_path / "bus.log")
    sender, other = _raw_sender(), open_udp_bus(channel)
    try:
        for i in range(50):
            sender.sendto(GARBAGE if i % 2 else BAD_FRAME, (endpoint.group, endpoint.port))
        other.send(can.Message(arbitration_id=0x701, data=[0x05], is_extended_id=False))
        deadline = time.monotonic() + 2.0
        while observer.nmt_state is None and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        sender.close()
        other.shutdown()
        logged = sniffer.stop()
        observer.close()
    assert observer.nmt_state == 5, "the observer must hear the heartbeat after the datagrams"
    assert observer.counters.undecodable_frames == 50
    assert logged == 1 and sniffer.dropped == {"undecodable_frames": 50}
