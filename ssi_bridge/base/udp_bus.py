"""CAN over UDP multicast between processes and hosts: python-can's ``udp_multicast`` interface.

The simulated station runs in its own process (or on another host) and meets the master on
python-can's ``udp_multicast`` bus: every CAN frame is one msgpack datagram to a multicast
group, the wire format of python-can, so any python-can tool on the same group sees the
traffic. :class:`UdpCanBus` is that interface with what a CAN wire needs:

* a sender does not receive its own frames (a CAN controller does not either; python-can's
  bus would, through multicast loop-back): frames go out through a second socket and
  datagrams from that socket's address are dropped, by the kernel where it takes a socket
  filter (Linux: the receive thread does not even wake up for them), else on receipt;
* the group is joined on one chosen interface (``127.0.0.1`` by default) and sent from it,
  so a station on the same host never puts a frame on the LAN;
* the receive socket is bound to the group address itself (not 0.0.0.0), so the kernel
  hands it only datagrams sent to the group: a datagram unicast to the port (``127.0.0.1:PORT``
  or any address of the host) never reaches the bus; with ``IP_MULTICAST_ALL`` off it hears
  only its own group even when another bus on the machine uses the same port;
* a datagram that is not a python-can CAN frame raises :class:`UndecodableFrame` (a
  ``can.CanOperationError``, as python-can's own udp_multicast raises) with what was wrong;
  the receive paths of master and station (``base/rx_guard.py``) count and drop it and go on;
* the receive queue is as deep as the kernel allows (``RECEIVE_BUFFER_BYTES``): a process
  starved of CPU for a moment reads the frames late, it does not lose them.

A bus without filters receives in one step (``recv``: the socket waits for the datagram, the
datagram becomes one frame, ``base/udp_frames.py``) and packs a frame it sends in one
(python-can's wire format, byte for byte); with filters ``recv`` is python-can's own loop.

The channel string is ``GROUP[:PORT][@INTERFACE_ADDRESS]``, e.g. ``239.74.163.2:43113@127.0.0.1``.
Receive timestamps are the kernel's (``SO_TIMESTAMPNS``, ``time.time()`` base), as python-can
sets them. The datagram also carries the sender's ``can.Message.timestamp`` (python-can packs
it): on a :class:`~ssi_bridge.sim.gateway.bus.WireBus` that is the frame's end on the simulated
wire, stamped before the sender's thread slept until then and sent. A received frame is a
:class:`UdpFrame` that keeps it as :attr:`UdpFrame.wire_time`: under CPU load the sender
wakes late, so the receive time is late by as much, the wire time is not.
"""

from __future__ import annotations

import errno
import hashlib
import ipaddress
import logging
import socket
import struct
import time
from dataclasses import dataclass

import can

from ssi_bridge.base.can_compat import SO_TIMESTAMPNS, MulticastBus, MulticastSockets
from ssi_bridge.base.own_frames import drop_own_frames, own_frames_filter
from ssi_bridge.base.udp_frames import (
    WIRE_TIME_PLAUSIBLE, UdpFrame, UndecodableFrame, pack_frame, unpack_frame, wire_time_of,
)
from ssi_bridge.exceptions import ConfigError

logger = logging.getLogger(__name__)

#: python-can's default udp_multicast port
DEFAULT_PORT = 43113
#: the interface a station on the same host is reached through
LOOPBACK = "127.0.0.1"
#: Linux socket option: deliver only the groups this socket joined (in.h)
IP_MULTICAST_ALL = 49
#: receive queue asked for (SO_RCVBUF; the kernel caps it at net.core.rmem_max): a CAN wire
#: loses no frame because a reader was late, so a starved process reads them late instead
#: (the default 208 kB holds ~256 datagrams: 85 ms of a 1 kHz cycle with two slots)
RECEIVE_BUFFER_BYTES = 4 * 1024 * 1024
#: the receive timestamp's control message: struct timespec (python-can's layout)
_TIMESPEC = struct.Struct("@ll").unpack
#: what a receive step returns for a datagram it dropped (its own frame, a CAN FD frame)
_DROPPED = object()
#: derived groups live in the administratively scoped 239.74.0.0/16 (RFC 2365)
_DERIVED_NET = (239, 74)
#: derived ports: above Linux's ephemeral range (net.ipv4.ip_local_port_range, 32768-60999 by
#: default), where any socket bound to port 0 (DDS's, a client's) may hold a port without
#: SO_REUSEADDR and the bus's bind then fails
_DERIVED_PORTS = (61000, 65536)
#: DDS (RTPS port mapping: 7400 + 250 x domain id, unicast ports at offsets 10 + 2 x
#: participant and 11 + 2 x participant, bound without SO_REUSEADDR) uses the derived range
#: for ROS_DOMAIN_ID 215-232: derived ports keep to offsets 160-249 of each domain's block,
#: beyond the unicast ports of a domain's first 75 participants on the host
_DDS_PORT_BASE, _DDS_DOMAIN_GAIN, _DDS_FREE_OFFSET = 7400, 250, 160
_PORTS = tuple(p for p in range(*_DERIVED_PORTS)
               if (p - _DDS_PORT_BASE) % _DDS_DOMAIN_GAIN >= _DDS_FREE_OFFSET)
#: where Linux keeps its ephemeral port range
_EPHEMERAL_RANGE_FILE = "/proc/sys/net/ipv4/ip_local_port_range"
@dataclass(frozen=True)
class Endpoint:
    """Where a udp_multicast CAN bus meets: group, UDP port, and the local interface address."""

    group: str
    port: int = DEFAULT_PORT
    interface: str = LOOPBACK

    def __post_init__(self) -> None:
        try:
            group = ipaddress.IPv4Address(self.group)
            ipaddress.IPv4Address(self.interface)
        except ValueError as err:
            raise ConfigError(f"udp_multicast channel: {err} (IPv4 addresses only)") from None
        if not group.is_multicast:
            raise ConfigError(f"udp_multicast channel: {self.group} is not a multicast group "
                              "(224.0.0.0/4)")
        if not 1 <= self.port <= 65535:
            raise ConfigError(f"udp_multicast channel: port {self.port} outside 1-65535")

    @property
    def channel(self) -> str:
        """The channel string that parses back to this endpoint."""
        return f"{self.group}:{self.port}@{self.interface}"


def parse_channel(channel: str) -> Endpoint:
    """``GROUP[:PORT][@INTERFACE_ADDRESS]`` -> :class:`Endpoint` (ConfigError when malformed)."""
    text, _, interface = str(channel).partition("@")
    group, _, port = text.partition(":")
    try:
        port_number = int(port) if port else DEFAULT_PORT
    except ValueError:
        raise ConfigError(f"udp_multicast channel {channel!r}: port {port!r} is not a number; "
                          "use GROUP[:PORT][@INTERFACE_ADDRESS]") from None
    return Endpoint(group, port_number, interface or LOOPBACK)


def ephemeral_ports() -> range | None:
    """This machine's ephemeral UDP/TCP port range (Linux), or None where it cannot be read."""
    try:
        with open(_EPHEMERAL_RANGE_FILE, encoding="ascii") as f:
            low, high = (int(v) for v in f.read().split())
    except (OSError, ValueError):
        return None
    return range(low, high + 1)


def _port_taken(port: int) -> str:
    """Why binding ``port`` said EADDRINUSE, and what to do, for the error message."""
    ephemeral = ephemeral_ports()
    if ephemeral is not None and port in ephemeral:
        return (f"port {port} lies in this machine's ephemeral range {ephemeral.start}-"
                f"{ephemeral.stop - 1}, where any socket may hold it; choose a port outside it")
    return f"another socket holds port {port} without SO_REUSEADDR"


def derive_channel(name: str, interface: str = LOOPBACK) -> str:
    """A group and port of their own for a bus named ``name`` (e.g. the node's bus.channel).

    A hash of the name picks 239.74.x.y and a port in 61000-65535 (above Linux's ephemeral
    ports) that no DDS domain's unicast port takes (:data:`_PORTS`), so nodes (and test runs)
    with different channel names never share a group and port.

    :param interface: the local interface address the group is joined on
    :returns: the channel text, ``group:port@interface``
    :raises ConfigError: ``interface`` is no IPv4 address
    """
    digest = hashlib.sha256(str(name).encode()).digest()
    x, y = digest[0], max(1, digest[1])
    port = _PORTS[int.from_bytes(digest[2:4], "big") % len(_PORTS)]
    return Endpoint(f"{_DERIVED_NET[0]}.{_DERIVED_NET[1]}.{x}.{y}", port, interface).channel


class _GroupSockets(MulticastSockets):
    """python-can's multicast socket pair logic, joined and sent on one interface address."""

    def __init__(self, endpoint: Endpoint, hop_limit: int) -> None:
        self.endpoint = endpoint
        try:
            super().__init__(endpoint.group, endpoint.port, hop_limit, self._open_receive_socket)
        except can.CanInitializationError as err:  # python-can's text hides the OS error
            cause = err.__cause__
            if not isinstance(cause, OSError):
                raise
            hint = f" ({_port_taken(endpoint.port)})" if cause.errno == errno.EADDRINUSE else ""
            raise can.CanInitializationError(
                f"cannot bind its receive socket: {cause.strerror or cause}{hint}") \
                from cause
        iface = socket.inet_aton(endpoint.interface)
        send = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            send.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL,
                            struct.pack("@I", hop_limit))
            send.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, iface)
            send.bind((endpoint.interface, 0))
        except OSError as err:
            send.close()
            self.receive_socket.close()
            raise can.CanInitializationError(
                f"cannot send to {endpoint.channel}: {err}") from err
        self.send_socket = send
        #: datagrams from this address are this bus's own frames
        self.own_address = send.getsockname()
        #: True when the kernel drops them before they reach the receive queue
        self.kernel_drops_own = drop_own_frames(self.receive_socket, self.own_address)

    def _open_receive_socket(self) -> socket.socket:
        """The receive socket: python-can's options, bound to GROUP:PORT (not 0.0.0.0:PORT),
        the group joined on the endpoint's interface only."""
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        group = socket.inet_aton(self.group)
        iface = socket.inet_aton(self.endpoint.interface)
        try:
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL,
                            struct.pack("@I", self.hop_limit))
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
            sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
            self.timestamp_nanosecond = True
            # the kernel caps this at net.core.rmem_max (the default queue holds ~256 frames)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
            # the destination must be the group: unicast datagrams to the port are not ours
            sock.bind((self.group, self.port))
        except OSError as err:
            sock.close()
            raise can.CanInitializationError("could not create or configure socket") from err
        try:
            sock.setsockopt(socket.IPPROTO_IP, IP_MULTICAST_ALL, 0)
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, group + iface)
        except OSError as err:
            sock.close()
            raise can.CanInitializationError(
                f"cannot join {self.group} on {self.endpoint.interface}: {err}") from err
        return sock

    def send(self, data: bytes, timeout: float | None = None) -> None:
        try:
            self.send_socket.sendto(data, (self.group, self.port))
        except OSError as err:
            raise can.CanOperationError(f"failed to send to {self.endpoint.channel}: {err}") \
                from err

    def shutdown(self) -> None:
        super().shutdown()
        self.send_socket.close()


class UdpCanBus(MulticastBus):
    """python-can's ``udp_multicast`` bus on one :class:`Endpoint`, without its own frames."""

    def __init__(self, channel: str, hop_limit: int = 1, **kwargs: object) -> None:
        endpoint = parse_channel(channel)
        # python-can's constructor would open sockets on every interface: these instead
        self.sockets = _GroupSockets(endpoint, hop_limit)
        super().__init__(endpoint.channel, self.sockets, **kwargs)
        self.endpoint = endpoint
        self.channel_info = f"udp_multicast {endpoint.channel}"
        sockets = self.sockets
        self._receive_socket = sockets.receive_socket
        # a blocking socket whose receive waits at most SO_RCVTIMEO (set per timeout asked
        # for): one recvmsg per frame, no poll before it
        self._receive_socket.settimeout(None)
        #: the wait SO_RCVTIMEO is set to (None: none, it waits for ever)
        self._socket_wait: float | None = None
        self._max_bytes = sockets.max_buffer
        self._ancillary_bytes = sockets.received_ancillary_buffer_size
        self._own_address = sockets.own_address
        self._send_datagram = sockets.send_socket.sendto
        self._group_address = (endpoint.group, endpoint.port)

    @property
    def receive_buffer_bytes(self) -> int:
        """The receive queue the kernel granted (SO_RCVBUF: twice the bytes asked for, up to
        net.core.rmem_max; :data:`RECEIVE_BUFFER_BYTES`)."""
        return int(self.sockets.receive_socket.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF))

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send ``msg`` (python-can's wire format, ``base/udp_frames.pack_frame``); ``timeout``
        is not used (a datagram is sent at once or fails).

        :raises can.CanOperationError: a CAN FD frame (this bus is classic CAN), or the
            socket's error (its cause)
        """
        if msg.is_fd:
            raise can.CanOperationError("cannot send FD message over bus with CAN FD disabled")
        data = pack_frame(msg)
        try:
            self._send_datagram(data, self._group_address)
        except OSError as err:
            raise can.CanOperationError(f"failed to send to {self.endpoint.channel}: {err}") \
                from err

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """The next frame of another sender, None after ``timeout`` s (None: wait for one).

        Without filters one receive step per frame; with filters python-can's ``recv`` loop.

        :raises UndecodableFrame: a datagram on the group that is not a CAN frame
        :raises can.CanOperationError: the socket failed (its OSError the cause)
        """
        if self.filters:
            return super().recv(timeout)
        msg = self._receive_step(timeout)
        if msg is _DROPPED:
            return self._receive_after_drop(timeout)
        return msg  # type: ignore[return-value]  # a frame or None

    def _receive_after_drop(self, timeout: float | None) -> can.Message | None:
        """:meth:`recv` once a datagram was dropped: the next frame within what is left of
        ``timeout`` (counted from here: a dropped datagram took a moment)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            msg = self._receive_step(left)
            if msg is not _DROPPED:
                return msg  # type: ignore[return-value]  # a frame or None
            if left == 0.0:
                return None

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        msg = self._receive_step(timeout)
        return (None if msg is _DROPPED else msg), False  # type: ignore[return-value]

    def _set_wait(self, timeout: float | None) -> None:
        """Have a receive wait at most ``timeout`` s (> 0; None: for ever): SO_RCVTIMEO."""
        seconds, micros = 0, 0
        if timeout is not None:
            seconds = int(timeout)
            micros = max(int((timeout - seconds) * 1e6), 0 if seconds else 1)  # 0 0: for ever
        self._receive_socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO,
                                        struct.pack("@ll", seconds, micros))
        self._socket_wait = timeout

    def _receive_step(self, timeout: float | None) -> object:
        """One datagram within ``timeout`` (s; None: wait): its frame, None when none came,
        :data:`_DROPPED` for the bus's own frame or a CAN FD frame."""
        sock = self._receive_socket
        flags = 0
        if timeout is not None and timeout <= 0.0:
            flags = socket.MSG_DONTWAIT
        elif timeout != self._socket_wait:
            self._set_wait(timeout)
        try:
            data, ancillary, _flags, sender = sock.recvmsg(self._max_bytes,
                                                           self._ancillary_bytes, flags)
        except BlockingIOError:  # nothing came within SO_RCVTIMEO (or waiting: MSG_DONTWAIT)
            return None
        except OSError as err:
            raise can.CanOperationError(
                f"failed to receive on {self.endpoint.channel}: {err}") from err
        if len(ancillary) != 1:
            raise can.CanOperationError(
                "Only requested a single extra field but got a different amount")
        level, kind, stamp = ancillary[0]
        if level != socket.SOL_SOCKET or kind != SO_TIMESTAMPNS:
            raise can.CanOperationError("received control message type that was not requested")
        seconds, nanoseconds = _TIMESPEC(stamp)
        if nanoseconds >= 1e9:
            raise can.CanOperationError(
                f"Timestamp nanoseconds field was out of range: {nanoseconds} not less than 1e9")
        if sender[:2] == self._own_address:
            return _DROPPED  # our own frame looped back (where no socket filter dropped it)
        try:
            msg = unpack_frame(data, seconds + nanoseconds * 1.0e-9)
        except Exception as err:  # noqa: BLE001 - a foreign datagram on the group
            raise UndecodableFrame(
                f"could not unpack received message: {len(data)} bytes from "
                f"{sender[0]}:{sender[1]} ({type(err).__name__}: {err})") from err
        if msg.is_fd:
            return _DROPPED
        return msg


__all__ = ["DEFAULT_PORT", "Endpoint", "LOOPBACK", "UdpCanBus", "UdpFrame", "UndecodableFrame",
           "WIRE_TIME_PLAUSIBLE", "derive_channel", "drop_own_frames", "open_udp_bus",
           "own_frames_filter", "pack_frame", "parse_channel", "unpack_frame", "wire_time_of"]


def open_udp_bus(channel: str) -> can.BusABC:
    """Open a :class:`UdpCanBus` on ``channel`` (``GROUP[:PORT][@INTERFACE_ADDRESS]``)."""
    return UdpCanBus(channel)
