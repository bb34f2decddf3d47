"""Canaries of python-can's udp_multicast internals behind base/can_compat.py
``MulticastSockets`` and ``MulticastBus`` (on which base/udp_bus.py builds its bus): a
python-can release that renamed one fails here, by name, on real sockets."""

from __future__ import annotations

import inspect
import os
import socket

import can
import pytest

from ssi_bridge.base import can_compat
from ssi_bridge.base.udp_bus import UdpCanBus, derive_channel


def test_the_socket_hook_and_the_bus_attribute_are_pythons_cans() -> None:
    """``GeneralPurposeUdpMulticastBus.__init__`` opens its receive socket through
    ``_create_socket`` and keeps it as ``_socket``; ``UdpMulticastBus`` sends, receives and
    shuts down through ``_multicast``."""
    general = can_compat.GeneralPurposeUdpMulticastBus
    init = inspect.getsource(general.__init__)
    assert "self._create_socket(" in init and "self._socket = " in init
    for method in (can_compat.UdpMulticastBus.send, can_compat.UdpMulticastBus.shutdown,
                   can_compat.UdpMulticastBus.fileno):
        assert "self._multicast." in inspect.getsource(method), method.__qualname__
    assert can.BusABC._can_protocol is can.CanProtocol.CAN_20, (
        "MulticastBus skips UdpMulticastBus.__init__: its protocol is BusABC's default")


def test_a_bus_on_its_own_sockets_sends_receives_and_shuts_them_down(
        request: pytest.FixtureRequest) -> None:
    channel = derive_channel(f"compat-{os.getpid()}-{request.node.name}")
    a, b = UdpCanBus(channel), UdpCanBus(channel)
    try:
        assert isinstance(a, can_compat.MulticastBus)
        assert isinstance(a.sockets, can_compat.MulticastSockets)
        assert a.protocol is can.CanProtocol.CAN_20
        receive = a.sockets.receive_socket
        assert isinstance(receive, socket.socket) and a.fileno() == receive.fileno()
        assert receive.getsockname() == (a.endpoint.group, a.endpoint.port)
        a.send(can.Message(arbitration_id=0x181, data=b"\x01\x02", is_extended_id=False))
        msg = b.recv(5.0)
        assert msg is not None and msg.arbitration_id == 0x181 and bytes(msg.data) == b"\x01\x02"
        assert a.recv(0.05) is None, "no frame of its own"
    finally:
        a.shutdown()
        b.shutdown()
    assert can_compat.is_shut_down(a) and receive.fileno() == -1
