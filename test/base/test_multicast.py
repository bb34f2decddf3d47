"""CAN over UDP multicast (python-can's udp_multicast): what a CAN wire between processes needs.

A CAN controller does not receive its own frames; a bus hears only its own group; a channel
string names group, port and interface (base/udp_bus.py). Real sockets on loopback.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from collections.abc import Iterator

import can
import pytest

from ssi_bridge.exceptions import BusError, ConfigError
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import open_bus
from ssi_bridge.base.udp_bus import (
    DEFAULT_PORT, RECEIVE_BUFFER_BYTES, Endpoint, UdpCanBus, derive_channel, ephemeral_ports,
    open_udp_bus, parse_channel)
from ssi_bridge.protocol.settings import load_params_file, station_settings


@pytest.fixture
def name(request: pytest.FixtureRequest) -> str:
    """A channel name unique to this test run."""
    return f"mc-{os.getpid()}-{request.node.name}"


@pytest.fixture
def pair(name: str) -> Iterator[tuple[can.BusABC, can.BusABC]]:
    cfg = BusConfig(interface="udp_multicast", channel=derive_channel(name))
    a, b = open_bus(cfg), open_bus(cfg)
    yield a, b
    a.shutdown()
    b.shutdown()


def _frame(can_id: int, data: bytes = b"") -> can.Message:
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False)


def test_a_frame_reaches_the_other_bus_with_a_receive_timestamp(pair) -> None:
    a, b = pair
    a.send(_frame(0x181, bytes(range(8))))
    msg = b.recv(5.0)
    assert msg is not None and msg.arbitration_id == 0x181 and bytes(msg.data) == bytes(range(8))
    assert msg.timestamp > 0  # the kernel's receive time (SO_TIMESTAMPNS)


def test_a_reader_late_by_a_burst_loses_no_frame(name: str) -> None:
    """A CAN wire loses no frame because a receiver's process was starved of CPU for a
    moment: the receive queue is as deep as the kernel allows (RECEIVE_BUFFER_BYTES, capped
    at net.core.rmem_max). With the kernel's default queue (208 kB) 256 of 3000 came through."""
    a, b = open_udp_bus(derive_channel(name)), open_udp_bus(derive_channel(name))
    try:
        _burst_received_whole(a, b)
    finally:
        a.shutdown()
        b.shutdown()


def _burst_received_whole(a: can.BusABC, b: UdpCanBus) -> None:
    rmem_max = int(open("/proc/sys/net/core/rmem_max").read())
    granted = b.receive_buffer_bytes
    assert granted >= 2 * min(RECEIVE_BUFFER_BYTES, rmem_max), granted
    burst = min(2000, granted // 1024)  # a datagram of a CAN frame takes < 1 kB of the queue
    for k in range(burst):
        a.send(_frame(0x181, k.to_bytes(2, "big")))
    got = []
    while (msg := b.recv(0.5)) is not None:
        got.append(int.from_bytes(msg.data, "big"))
    assert got == list(range(burst)), f"{len(got)} of {burst} frames received"


def test_a_bus_does_not_receive_its_own_frames(pair) -> None:
    a, b = pair
    a.send(_frame(0x080))
    b.send(_frame(0x701, b"\x05"))
    got_b = b.recv(5.0)
    got_a = a.recv(5.0)
    assert got_b is not None and got_b.arbitration_id == 0x080
    assert got_a is not None and got_a.arbitration_id == 0x701
    assert a.recv(0.2) is None and b.recv(0.2) is None  # nothing echoed back


def test_buses_on_other_channels_do_not_hear_each_other(name: str) -> None:
    first = open_bus(BusConfig(interface="udp_multicast", channel=derive_channel(name + "1")))
    other = open_bus(BusConfig(interface="udp_multicast", channel=derive_channel(name + "2")))
    same = open_bus(BusConfig(interface="udp_multicast", channel=derive_channel(name + "1")))
    try:
        first.send(_frame(0x123, b"\x01"))
        assert same.recv(5.0) is not None
        assert other.recv(0.3) is None
    finally:
        for bus in (first, other, same):
            bus.shutdown()


def test_derived_channels_are_stable_and_distinct() -> None:
    assert derive_channel("test_7_0") == derive_channel("test_7_0")
    channels = {derive_channel(f"test_{d}_{n}") for d in range(1, 233) for n in range(4)}
    assert len(channels) == 232 * 4  # every test domain and node index: its own group:port


def test_derived_ports_lie_above_the_ephemeral_ports() -> None:
    """A socket bound to port 0 (DDS opens dozens) takes a port in Linux's ephemeral range
    and, without SO_REUSEADDR, keeps a bus from binding it: derived ports stay above it."""
    ports = {parse_channel(derive_channel(f"test_{d}_{n}")).port
             for d in range(1, 233) for n in range(4)}
    assert min(ports) >= 61000 and max(ports) <= 65535
    # nor a DDS unicast port (RTPS port mapping 7400 + 250 d + 10 / 11 + 2 p) of any domain
    # 0-232 with up to 75 participants on the host
    dds = {7400 + 250 * d + off + 2 * p for d in range(233) for p in range(75) for off in (10, 11)}
    assert not ports & dds, sorted(ports & dds)[:5]
    ephemeral = ephemeral_ports()
    if ephemeral is not None:
        assert not ports & set(ephemeral), (ephemeral, sorted(ports & set(ephemeral))[:5])


def test_the_station_bus_of_a_node_depends_on_its_domain(monkeypatch) -> None:
    """Two nodes of one name and bus.channel on different ROS_DOMAIN_IDs get buses of their
    own, each a derived port that keeps to the DDS-free offsets; domain 0 (or none) keeps the
    bus of bus.channel alone, and a udp_multicast channel given by the user stays as given."""
    from ssi_bridge.ros.params import NodeSettings  # the node's settings, as the node has them
    from ssi_bridge.sim.supervisor.station import with_station_bus

    s = NodeSettings(joints=(), bus_channel="robot")
    by_domain = {d: with_station_bus(s, "/ssi_bridge", d).bus_channel for d in range(233)}
    assert len(set(by_domain.values())) == 233, "a bus of its own for every domain"
    assert by_domain[0] == derive_channel("robot")
    dds = {7400 + 250 * d + off + 2 * p for d in range(233) for p in range(75) for off in (10, 11)}
    ports = {parse_channel(c).port for c in by_domain.values()}
    assert min(ports) >= 61000 and not ports & dds
    monkeypatch.setenv("ROS_DOMAIN_ID", "42")
    assert with_station_bus(s, "/ssi_bridge").bus_channel == by_domain[42]
    monkeypatch.setenv("ROS_DOMAIN_ID", "")
    assert with_station_bus(s, "/ssi_bridge").bus_channel == by_domain[0]
    given = NodeSettings(joints=(), bus_interface="udp_multicast", bus_channel="239.1.2.3:61234")
    assert with_station_bus(given, "/ssi_bridge", 42).bus_channel == "239.1.2.3:61234"


def test_a_taken_port_is_named_with_the_reason() -> None:
    """A port held on every address by a socket without SO_REUSEADDR: the error says so
    (python-can's own message is only "could not create or configure socket") and names the
    ephemeral range. (A socket on one address, 127.0.0.1:port, no longer stands in the way:
    the bus binds GROUP:PORT.)"""
    holder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    holder.bind(("", 0))  # as DDS's and many clients' sockets do
    port = holder.getsockname()[1]
    try:
        with pytest.raises(BusError) as err:
            open_bus(BusConfig(interface="udp_multicast", channel=f"239.74.250.9:{port}"))
    finally:
        holder.close()
    text = str(err.value)
    assert "Address already in use" in text, text
    ephemeral = ephemeral_ports()
    if ephemeral is not None and port in ephemeral:
        assert f"ephemeral range {ephemeral.start}-{ephemeral.stop - 1}" in text, text


#: ports of this test run only (parallel runs have other pids)
_PORT = 30000 + 2 * (os.getpid() % 5000)


@pytest.mark.parametrize("other", [f"239.74.200.2:{_PORT}", f"239.74.200.1:{_PORT + 1}"],
                         ids=["other_group_same_port", "same_group_other_port"])  # no pid in ids
def test_a_bus_hears_only_its_group_and_port(other: str) -> None:
    """Group and port together isolate (IP_MULTICAST_ALL off): same port, other group is quiet."""
    here = f"239.74.200.1:{_PORT}"
    mine = open_bus(BusConfig(interface="udp_multicast", channel=here))
    peer = open_bus(BusConfig(interface="udp_multicast", channel=here))
    stranger = open_bus(BusConfig(interface="udp_multicast", channel=other))
    try:
        stranger.send(_frame(0x321))
        peer.send(_frame(0x123))
        got = mine.recv(5.0)
        assert got is not None and got.arbitration_id == 0x123
        assert mine.recv(0.3) is None
    finally:
        for bus in (mine, peer, stranger):
            bus.shutdown()


@pytest.mark.parametrize("text, endpoint", [
    ("239.1.2.3", Endpoint("239.1.2.3", DEFAULT_PORT, "127.0.0.1")),
    ("239.1.2.3:5000", Endpoint("239.1.2.3", 5000, "127.0.0.1")),
    ("239.1.2.3:5000@10.201.0.1", Endpoint("239.1.2.3", 5000, "10.201.0.1")),
])
def test_channel_strings(text: str, endpoint: Endpoint) -> None:
    assert parse_channel(text) == endpoint
    assert parse_channel(endpoint.channel) == endpoint


@pytest.mark.parametrize("text, words", [
    ("10.0.0.1", "not a multicast group"),
    ("239.1.2.3:x", "is not a number"),
    ("239.1.2.3:70000", "outside 1-65535"),
    ("ssi_bridge", "IPv4"),
])
def test_bad_channel_strings_say_why(text: str, words: str) -> None:
    with pytest.raises(ConfigError, match=words):
        parse_channel(text)


def test_another_process_on_the_channel_is_heard(name: str) -> None:
    """Two processes: the point of the interface (the station runs as a child process)."""
    channel = derive_channel(name)
    bus = open_bus(BusConfig(interface="udp_multicast", channel=channel))
    code = ("import sys, can; from ssi_bridge.sim.gateway.bus import open_bus;"
            "from ssi_bridge.protocol.settings import BusConfig;"
            f"b = open_bus(BusConfig(interface='udp_multicast', channel='{channel}'));"
            "m = b.recv(10.0); b.send(can.Message(arbitration_id=m.arbitration_id + 1,"
            " data=m.data, is_extended_id=False)); b.shutdown()")
    child = subprocess.Popen([sys.executable, "-c", code])
    try:
        reply = None
        for _ in range(100):  # until the child listens: resend, as a master would
            bus.send(_frame(0x600, b"\x40\x00\x10\x00"))
            reply = bus.recv(0.1)
            if reply is not None:
                break
        assert reply is not None and reply.arbitration_id == 0x601
        assert bytes(reply.data) == b"\x40\x00\x10\x00"
    finally:
        bus.shutdown()
        child.wait(10)


def test_params_file_sections_and_nesting() -> None:
    import io
    text = """
/**:
  ros__parameters:
    joints: [a, b]
    bus.channel: from_wildcard
other_node:
  ros__parameters:
    bus.channel: not_mine
/robot/ssi_bridge:
  ros__parameters:
    bus: {interface: udp_multicast, channel: "239.1.2.3:4000"}
    a: {family: TTK70, motion: {kind: still}}
    b.slot: 4
"""
    values = load_params_file(io.StringIO(text))
    s = station_settings(values)
    assert s.bus.interface == "udp_multicast" and s.bus.channel == "239.1.2.3:4000"
    assert [(j.name, j.slot, j.family, j.motion.kind) for j in s.joints] == [
        ("a", 1, "TTK70", "still"), ("b", 4, "GENERIC", "constant")]
