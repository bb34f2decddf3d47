"""Every use of python-can's private API in one place (python-can 4.6), checked by a canary.

What the simulated wire and the CAN-over-UDP interface need that python-can does not offer
publicly:

* :func:`recv_step`: one receive step of a wrapped bus (``BusABC._recv_internal`` and
  ``_matches_filters``), so a wrapper's ``recv`` is python-can's own loop around it, and the
  hot receive path of every frame skips a second loop (``sim/gateway/bus.py``, ``wire_bus.py``);
* :func:`steps_itself`: whether a bus receives through python-can's ``BusABC.recv`` (then
  :func:`recv_step` is its step);
* :func:`is_shut_down`: ``BusABC._is_shutdown``;
* the udp_multicast interface's internals ``SO_TIMESTAMPNS``, ``pack_message`` and
  ``unpack_message`` (its wire format, ``base/udp_frames.py``), and
  :class:`MulticastSockets` / :class:`MulticastBus`, python-can's socket pair
  (``GeneralPurposeUdpMulticastBus``: its ``_create_socket`` hook and ``_socket``) and its
  ``UdpMulticastBus`` (``_multicast``) on sockets of the caller's (``base/udp_bus.py``
  builds its bus on them).

A wrapper that overrides ``BusABC._send_periodic_internal`` (the periodic-task hook,
``sim/gateway/bus.py``) relies on its signature, which the canary also checks.
``test/base/test_library_compat.py`` fails on a python-can whose private names changed.
"""

from __future__ import annotations

import socket
from collections.abc import Callable

import can
from can.interfaces.udp_multicast.bus import (  # noqa: F401 - re-exported for base/udp_bus.py
    SO_TIMESTAMPNS, GeneralPurposeUdpMulticastBus, UdpMulticastBus,
)
from can.interfaces.udp_multicast.utils import (  # noqa: F401 - re-exported
    pack_message, unpack_message,
)


def steps_itself(bus: can.BusABC) -> bool:
    """True when ``bus`` receives through python-can's own ``BusABC.recv`` loop."""
    return type(bus).recv is can.BusABC.recv


def recv_step(bus: can.BusABC, timeout: float | None) -> can.Message | None:
    """One receive step of ``bus`` (a frame, or None after ``timeout``), its filters applied."""
    msg, filtered = bus._recv_internal(timeout)
    if msg is not None and not filtered and not bus._matches_filters(msg):
        return None
    return msg


def recv_step_unfiltered(bus: can.BusABC, timeout: float | None) -> can.Message | None:
    """One receive step of ``bus`` that neither bus filters (the caller checked).

    :param timeout: at most this long (s; None: until a frame comes)
    :returns: the frame received, None when ``timeout`` passed
    """
    return bus._recv_internal(timeout)[0]


def is_shut_down(bus: can.BusABC) -> bool:
    """True once ``bus.shutdown()`` ran."""
    return bool(bus._is_shutdown)


class MulticastSockets(GeneralPurposeUdpMulticastBus):
    """python-can's multicast socket logic (``recv``, ``send``, ``fileno``, ``shutdown``) on a
    receive socket the caller opens.

    :param group: the multicast group address
    :param port: its UDP port
    :param hop_limit: the multicast TTL
    :param open_receive: opens, configures and binds the receive socket (python-can's
        constructor calls it once; it raises ``can.CanInitializationError``)
    """

    def __init__(self, group: str, port: int, hop_limit: int,
                 open_receive: Callable[[], socket.socket]) -> None:
        self._open_receive = open_receive
        super().__init__(group, port, hop_limit)

    def _create_socket(self, address_family: socket.AddressFamily) -> socket.socket:
        return self._open_receive()

    @property
    def receive_socket(self) -> socket.socket:
        """The receive socket ``open_receive`` opened."""
        sock: socket.socket = self._socket
        return sock


class MulticastBus(UdpMulticastBus):
    """python-can's ``udp_multicast`` bus on ``sockets`` of the caller's instead of those its
    constructor opens on every interface (``send``, ``fileno`` and ``shutdown`` are python-can's,
    through ``sockets``; a subclass receives through ``sockets.recv``).

    :param channel: the channel it reports
    :param sockets: its sockets (shut down with it, or here when the bus cannot be made)
    """

    def __init__(self, channel: str, sockets: GeneralPurposeUdpMulticastBus,
                 **kwargs: object) -> None:
        try:
            can.BusABC.__init__(self, channel, **kwargs)  # type: ignore[arg-type]
        except BaseException:
            sockets.shutdown()
            raise
        self._multicast = sockets


__all__ = ["GeneralPurposeUdpMulticastBus", "MulticastBus", "MulticastSockets", "SO_TIMESTAMPNS",
           "UdpMulticastBus", "is_shut_down", "pack_message", "recv_step",
           "recv_step_unfiltered", "steps_itself", "unpack_message"]
