"""The master's CAN bus: a plain python-can bus, canopen's network on it, what it has seen.

The master runs on whatever python-can bus it is given (socketcan, pcan, the CAN-over-UDP
interface of :mod:`ssi_bridge.base.udp_bus`, virtual): :func:`open_bus` opens one from a
:class:`~ssi_bridge.protocol.settings.BusConfig`, or the caller hands an open bus over
(:func:`take_bus`; the node's simulation supervisor hands over the simulated wire). Nothing
here simulates anything: frame loss, a muted gateway and the timed wire are faults and
models of the simulated station (``sim/``).

:class:`ReceiveWatch` wraps the master's bus to keep what the liveness check needs, the wire
time up to which the receive path has handled every frame (:meth:`ReceiveWatch.seen_until`),
through python-can's public ``recv``/``send`` only. :class:`MasterNetwork` is canopen's
``Network`` that reports every frame it sends (the bus load).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import can

from ssi_bridge.base.timebase import wire_now
from ssi_bridge.base.buses import open_python_can, take_bus
from ssi_bridge.base.canopen_compat import OwnListenerNetwork
from ssi_bridge.client.link import ReopeningBus
from ssi_bridge.protocol.settings import BusConfig

logger = logging.getLogger(__name__)

#: receive-thread wake-up period (s): bounds how long stopping a canopen Network takes
NOTIFIER_CYCLE = 0.05

#: opens a bus for a config: :func:`open_bus`, or the simulation supervisor's
BusOpener = Callable[[BusConfig], can.BusABC]


def open_bus(config: BusConfig) -> can.BusABC:
    """Open a new python-can bus for ``config`` (:func:`~ssi_bridge.base.buses.open_python_can`);
    the caller must ``shutdown()`` it. Raises BusError with the reason."""
    return open_python_can(config)


class ReceiveWatch(can.BusABC):
    """The master's bus, keeping the wire time up to which its receive path has seen the wire.

    ``recv`` and ``send`` pass straight through (python-can's public API of the wrapped bus).
    Where the wrapped bus is a simulated wire shared with a station in this process (it has a
    ``wire`` with ``undelivered_since()``), a frame of this process still on its way to the
    receivers holds the view back: its sender's thread may be the one stalled.

    :param inner: the bus to wrap (the opener's, a ReopeningBus or a handed-over bus)
    """

    def __init__(self, inner: can.BusABC) -> None:
        self._inner = inner
        self._wire = getattr(inner, "wire", None)
        #: newest timestamp of a frame received, and the wire time at which a receive last
        #: found nothing waiting
        self.rx_latest = 0.0
        self.rx_idle_at = 0.0
        super().__init__(channel=getattr(inner, "channel_info", "bus"))
        self.channel_info = str(getattr(inner, "channel_info", "bus"))

    @property
    def inner(self) -> can.BusABC:
        """The wrapped bus: the one the opener opened (behind a ReopeningBus, the one open
        now), or the bus handed over."""
        inner = self._inner
        if isinstance(inner, ReopeningBus) and inner.current is not None:
            return inner.current
        return inner

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send ``msg`` on the wrapped bus, waiting at most ``timeout`` s (None: its default)
        for room to send; raises what the wrapped bus raises (``can.CanError``)."""
        self._inner.send(msg, timeout)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """Receive one frame from the wrapped bus (None after ``timeout``) and note its time."""
        msg = self._inner.recv(timeout)
        wire = self._wire
        if msg is None:
            now = wire_now()
            self.rx_idle_at = now if wire is None else min(now, wire.undelivered_since())
            if self.rx_latest > now:  # stamped before the wall clock stepped back
                self.rx_latest = self.rx_idle_at
        elif msg.timestamp > self.rx_latest:
            ts = msg.timestamp
            self.rx_latest = ts if wire is None else min(ts, wire.undelivered_since())
        return msg

    def seen_until(self) -> float:
        """Wire time up to which every frame on the wire has been handled by this side."""
        seen = max(self.rx_latest, self.rx_idle_at)
        if self._wire is not None:
            seen = min(seen, self._wire.undelivered_since())
        return seen

    def shutdown(self) -> None:
        """Shut the wrapped bus down too."""
        super().shutdown()
        self._inner.shutdown()


class MasterNetwork(OwnListenerNetwork):
    """The master's canopen ``Network`` (``base/canopen_compat.OwnListenerNetwork``): its
    listener is ``client/receive.FrameListener``; :attr:`on_sent` counts the bus load."""


__all__ = ["BusOpener", "MasterNetwork", "NOTIFIER_CYCLE", "ReceiveWatch", "open_bus",
           "take_bus"]
