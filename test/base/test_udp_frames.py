"""The udp_multicast wire format read and written in one step is python-can's, byte for byte.

``base/udp_frames.py`` decodes a datagram into one frame and packs a frame without python-can's
generic path; whatever python-can's ``pack_message``/``unpack_message`` would make of the same
frame or datagram (the value, or the error) is what these make. A bus of ours and python-can's
own udp_multicast bus on one group hear each other both ways (``base/udp_bus.py``), and the
kernel drops a bus's own frames before its receive queue.
"""

from __future__ import annotations

import math
import os
import random
import socket
import struct
import time

import can
import msgpack
import pytest

from ssi_bridge.base.can_compat import pack_message, unpack_message
from ssi_bridge.base.udp_bus import UdpCanBus, UndecodableFrame, derive_channel, open_udp_bus
from ssi_bridge.base import udp_frames
from ssi_bridge.base.udp_frames import UdpFrame, pack_frame, unpack_frame, wire_time_of

FIELDS = tuple(n for n in can.Message.__slots__ if n != "__weakref__")


def _random_frame(rng: random.Random) -> can.Message:
    """A frame of any kind python-can sends: classic data, remote, error, extended, CAN FD."""
    kind = rng.choice(["data", "data", "remote", "error", "fd"])
    ext = rng.random() < 0.3
    aid = rng.randrange(0x20000000 if ext else 0x800)
    if kind == "fd":
        n = rng.choice([0, 8, 12, 16, 20, 24, 32, 48, 64])
        return can.Message(timestamp=rng.uniform(0, 2e9), arbitration_id=aid,
                           is_extended_id=ext, is_fd=True, data=rng.randbytes(n),
                           bitrate_switch=rng.random() < 0.5,
                           error_state_indicator=rng.random() < 0.5)
    if kind == "remote":
        return can.Message(timestamp=rng.uniform(0, 2e9), arbitration_id=aid,
                           is_extended_id=ext, is_remote_frame=True, dlc=rng.randrange(9))
    data = rng.randbytes(rng.randrange(9))
    return can.Message(timestamp=rng.choice([0.0, rng.uniform(0, 2e9)]), arbitration_id=aid,
                       is_extended_id=ext, is_error_frame=kind == "error", data=data,
                       channel=rng.choice([None, None, None, "can0", 1]))


def _fields(msg: can.Message) -> dict[str, object]:
    return {name: getattr(msg, name) for name in FIELDS}


def _same_as_python_can(datagram: bytes, received: float) -> None:
    """``unpack_frame`` gives what python-can's ``unpack_message(check=True)`` gives (with the
    receive time as timestamp), or raises what it raises."""
    try:
        expected = unpack_message(datagram, check=True)
    except Exception as err:  # noqa: BLE001 - the error is what is compared
        with pytest.raises(type(err)):
            unpack_frame(datagram, received)
        return
    got = unpack_frame(datagram, received)
    assert type(got) is UdpFrame
    sent = expected.timestamp
    expected.timestamp = received
    assert _fields(got) == _fields(expected)
    assert type(got.data) is bytearray
    assert got.wire_time == wire_time_of(sent, received)


def test_random_frames_pack_and_unpack_as_python_can() -> None:
    rng = random.Random(33)
    for _ in range(5000):
        msg = _random_frame(rng)
        datagram = pack_frame(msg)
        assert datagram == pack_message(msg)
        received = msg.timestamp + rng.choice([0.0, 2e-4, 3.0])
        _same_as_python_can(datagram, received)


def test_frames_of_a_known_layout_are_read_by_position_as_python_can_reads_them() -> None:
    """The second frame of a COB-ID, kind and length is read by its layout (learnt from the
    first): the same result as python-can's, and a datagram that differs from the layout
    anywhere else (a stamp python-can refuses, the FD flags, its length) is not taken by it."""
    rng = random.Random(5)
    for can_id, ext, kind in ((0x181, False, "data"), (0x1FFFFFF0, True, "data"),
                              (0x701, False, "remote"), (0x0C0, False, "error"),
                              (0x2E1, False, "data")):
        for n in range(9):
            for _ in range(3):
                msg = can.Message(timestamp=time.time(), arbitration_id=can_id,
                                  is_extended_id=ext, is_remote_frame=kind == "remote",
                                  is_error_frame=kind == "error",
                                  dlc=n if kind == "remote" else None,
                                  data=None if kind == "remote" else rng.randbytes(n))
                _same_as_python_can(pack_message(msg), msg.timestamp + 1e-4)
    assert udp_frames._LAYOUTS, "no layout learnt"
    known = pack_message(can.Message(timestamp=1.5, arbitration_id=0x181, is_extended_id=False,
                                     data=b"\x01\x02"))
    assert udp_frames._laid_out(known) is not None
    stamp = known.index(struct.pack(">d", 1.5))
    for odd in (-1.0, math.nan, math.inf):
        _same_as_python_can(known[:stamp] + struct.pack(">d", odd) + known[stamp + 8:], 1.5)
    for cut in (1, 3, 20):
        _same_as_python_can(known[:-cut], 1.5)
    _same_as_python_can(known + b"\xc0", 1.5)
    fd_on = pack_message(can.Message(timestamp=1.5, arbitration_id=0x181, is_extended_id=False,
                                      data=b"\x01\x02", is_fd=True))
    _same_as_python_can(fd_on, 1.5)


def _map(**changes: object) -> bytes:
    fields = {"timestamp": 1.5, "arbitration_id": 0x181, "is_extended_id": False,
              "is_remote_frame": False, "is_error_frame": False, "channel": None, "dlc": 2,
              "data": b"\x01\x02", "is_fd": False, "bitrate_switch": False,
              "error_state_indicator": False}
    fields.update(changes)
    return msgpack.packb({k: v for k, v in fields.items() if v is not ...}, use_bin_type=True)


@pytest.mark.parametrize("datagram", [
    _map(), _map(dlc=3), _map(is_remote_frame=True, is_error_frame=True),
    _map(is_remote_frame=True, dlc=9), _map(is_remote_frame=True, data=b"\x01", dlc=1),
    _map(arbitration_id=0x800), _map(arbitration_id=0x800, is_extended_id=True),
    _map(arbitration_id=0x20000000, is_extended_id=True), _map(arbitration_id=-1),
    _map(timestamp=-1.0), _map(timestamp=math.nan), _map(timestamp=math.inf), _map(timestamp=2),
    _map(dlc=9, data=bytes(9)), _map(bitrate_switch=True), _map(error_state_indicator=True),
    _map(is_fd=True, dlc=12, data=bytes(12)), _map(is_extended_id=1), _map(is_error_frame=1),
    _map(data=[1, 2]), _map(data="ab"), _map(dlc=None), _map(channel=...), _map(extra=1),
    _map(channel=[1, 2]), b"", b"\xc1", b"not msgpack", msgpack.packb([1, 2, 3]),
    msgpack.packb({"timestamp": 1.0}), _map()[:-3],
], ids=lambda d: d.hex()[:24])
def test_odd_datagrams_decode_or_fail_as_python_can(datagram: bytes) -> None:
    _same_as_python_can(datagram, 1.5002)


@pytest.mark.parametrize("msg", [
    can.Message(arbitration_id=0x80, data=b"", is_extended_id=False, timestamp=1),  # int stamp
    can.Message(arbitration_id=0x181, data=memoryview(b"\x01\x02"), is_extended_id=False),
    can.Message(arbitration_id=0x181, data=bytes(200), is_extended_id=False, is_fd=True,
                check=False),
    can.Message(arbitration_id=0x1FFFFFFF, data=b"\x01", is_extended_id=True),
], ids=["int-timestamp", "memoryview", "long-payload", "largest-extended-id"])
def test_frames_off_the_usual_path_pack_as_python_can(msg: can.Message) -> None:
    assert pack_frame(msg) == pack_message(msg)


def _default_interface(group: str, port: int) -> str:
    """The address the kernel sends a datagram to ``group`` from (python-can's bus sends
    through the default multicast interface)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.connect((group, port))
        return str(sock.getsockname()[0])
    except OSError as err:
        pytest.skip(f"no multicast route on this host: {err}")
    finally:
        sock.close()


def test_our_bus_and_python_cans_own_bus_hear_each_other() -> None:
    endpoint = derive_channel(f"interop-{os.getpid()}").split("@")[0]
    group, port = endpoint.split(":")
    ours = UdpCanBus(f"{endpoint}@{_default_interface(group, int(port))}")
    try:
        theirs = can.Bus(interface="udp_multicast", channel=group, port=int(port))
    except (OSError, can.CanError) as err:
        ours.shutdown()
        pytest.skip(f"python-can's udp_multicast bus cannot open here: {err}")
    rng = random.Random(7)
    try:
        for _ in range(40):
            msg = _random_frame(rng)
            if msg.is_fd:
                continue  # both buses are classic CAN
            msg.timestamp = time.time()
            ours.send(msg)
            got = theirs.recv(2.0)
            assert got is not None and got.equals(msg, timestamp_delta=None), (msg, got)
            theirs.send(msg)
            got = ours.recv(2.0)
            assert got is not None and got.equals(msg, timestamp_delta=None), (msg, got)
            assert got.wire_time == msg.timestamp  # the sender's stamp, python-can packs it
            assert theirs.recv(2.0) is not None  # python-can's bus hears its own frame
        assert ours.recv(0.05) is None, "our bus heard its own frames"
    finally:
        ours.shutdown()
        theirs.shutdown()


def test_the_kernel_drops_a_bus_own_frames_before_its_queue() -> None:
    channel = derive_channel(f"own-{os.getpid()}")
    a, b = open_udp_bus(channel), open_udp_bus(channel)
    try:
        assert a.sockets.kernel_drops_own
        for _ in range(5):
            a.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
        assert b.recv(1.0) is not None  # the other bus got them
        sock = a.sockets.receive_socket
        sock.settimeout(0.05)
        with pytest.raises(TimeoutError):
            sock.recvmsg(4096, 64)  # nothing queued: the kernel dropped them
        sock.settimeout(None)
        b.send(can.Message(arbitration_id=0x181, data=b"\x01", is_extended_id=False))
        got = a.recv(1.0)
        assert got is not None and got.arbitration_id == 0x181
    finally:
        a.shutdown()
        b.shutdown()


def test_an_undecodable_datagram_raises_and_the_next_frame_comes_through() -> None:
    channel = derive_channel(f"junk-{os.getpid()}")
    bus, other = open_udp_bus(channel), open_udp_bus(channel)
    group, port = channel.split("@")[0].split(":")
    junk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    junk.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
    try:
        junk.sendto(b"not a frame", (group, int(port)))
        with pytest.raises(UndecodableFrame, match="11 bytes from"):
            bus.recv(1.0)
        other.send(can.Message(arbitration_id=0x181, data=b"\x01", is_extended_id=False))
        got = bus.recv(1.0)
        assert got is not None and got.arbitration_id == 0x181
    finally:
        junk.close()
        bus.shutdown()
        other.shutdown()


def test_recv_returns_none_after_its_timeout_and_honours_filters() -> None:
    channel = derive_channel(f"filters-{os.getpid()}")
    bus, other = open_udp_bus(channel), open_udp_bus(channel)
    try:
        t0 = time.monotonic()
        assert bus.recv(0.1) is None
        assert 0.08 <= time.monotonic() - t0 < 1.0
        assert bus.recv(0.0) is None
        bus.set_filters([{"can_id": 0x181, "can_mask": 0x7FF, "extended": False}])
        other.send(can.Message(arbitration_id=0x182, data=b"", is_extended_id=False))
        other.send(can.Message(arbitration_id=0x181, data=b"", is_extended_id=False))
        got = bus.recv(1.0)
        assert got is not None and got.arbitration_id == 0x181
        assert bus.recv(0.05) is None
    finally:
        bus.shutdown()
        other.shutdown()
