"""One master per bus: before this master sends anything, nobody else may be driving the bus.

CiA 301 has one NMT master and one SYNC producer per network. Two bridges given the same bus
(two nodes with ``simulation.enabled: false`` on one interface, or two simulated nodes given
the same udp_multicast channel) would each SYNC, reset and configure the same stations. So
before its first frame the node listens :data:`MASTER_CHECK_S` on its bus for what only a
master sends (``client/foreign.py``: SYNC on 0x080, NMT commands on 0x000, SDO requests to its
stations on 0x600 + node id); a node that hears any of it does not start, and says in one line
what it heard and on which COB-ID. A master that SYNCs at 4 Hz or more (``publish_rate`` is
100 Hz by default) is always heard. Listening changes nothing on the bus, so the master
already running goes on undisturbed.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Sequence
from typing import Protocol

import can

from ssi_bridge.client.bus import open_bus
from ssi_bridge.client.foreign import describe_frame, master_frames
from ssi_bridge.exceptions import BusError
from ssi_bridge.protocol.settings import BusConfig

#: seconds the node listens before it sends its first frame
MASTER_CHECK_S = 0.3


def heard_masters(bus: can.BusABC, station_ids: Sequence[int], window: float) -> Counter[str]:
    """What ``bus`` carried of a master's frames within ``window`` s: words -> frames.

    A receive error (an undecodable datagram, an interface that fails) ends nothing: the
    window runs out. Error, remote and extended frames are not a master's.

    :param bus: the open bus to receive on
    :param station_ids: the node ids of this master's stations (SDO requests to them)
    :param window: how long to listen (s)
    """
    frames = master_frames(list(station_ids))
    heard: Counter[str] = Counter()
    end = time.monotonic() + window
    while (left := end - time.monotonic()) > 0:
        try:
            msg = bus.recv(min(left, 0.05))
        except (can.CanError, OSError, ValueError):
            time.sleep(min(left, 0.005))
            continue
        if msg is None or msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id:
            continue
        if msg.arbitration_id in frames:
            heard[describe_frame(msg.arbitration_id, bytes(msg.data), frames)] += 1
    return heard


def ensure_alone(config: BusConfig, station_ids: Sequence[int],
                 opener: Callable[[BusConfig], can.BusABC] | None = None,
                 window: float = MASTER_CHECK_S, *, listen_only: bool = False) -> None:
    """Listen ``window`` s on the bus of ``config`` (opened with ``opener``, default a plain
    python-can bus, and closed again); raise BusError naming another master's frames.

    Nothing is checked for a ``listen_only`` observer (it observes another master by design)
    nor on the in-process ``virtual`` bus (nobody else can be on it). A bus that cannot be
    opened is not checked either: whoever opens it next (the simulated station's start, the
    master) reports that with its own words.

    :param station_ids: the node ids of this master's stations
    """
    if listen_only or config.interface == "virtual":
        return
    try:
        bus = (opener or open_bus)(config)
    except BusError:
        return
    try:
        heard = heard_masters(bus, station_ids, window)
    finally:
        bus.shutdown()
    if heard:
        what = ", ".join(f"{n} x {words}" for words, n in heard.most_common(3))
        raise BusError(
            f"another CANopen master drives {config.interface}:{config.channel}: in {window:g} s "
            f"it sent {what}, none of it from this node; one master per bus (CiA 301): give "
            "this bridge a bus of its own (bus.channel) or observe with bus.listen_only")


class MasterSettings(Protocol):
    """What :func:`ensure_node_alone` reads of the node's settings (``NodeSettings``)."""

    @property
    def listen_only(self) -> bool:
        """True: the node only listens (another master serves the stations)."""

    @property
    def station_ids(self) -> tuple[int, ...]:
        """The node ids of the node's stations."""


def ensure_node_alone(config: BusConfig, settings: MasterSettings,
                      opener: Callable[[BusConfig], can.BusABC] | None = None) -> None:
    """:func:`ensure_alone` for a node: its stations, nothing when it only listens.

    :param config: the node's bus
    :param settings: the node's master settings (its stations, whether it only listens)
    :param opener: opens the bus (default: a plain python-can bus)
    :raises BusError: another master's frames were heard, naming them
    """
    ensure_alone(config, settings.station_ids, opener, listen_only=settings.listen_only)


__all__ = ["MASTER_CHECK_S", "MasterSettings", "ensure_alone", "ensure_node_alone",
           "heard_masters"]
