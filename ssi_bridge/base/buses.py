"""Open the python-can bus of a :class:`~ssi_bridge.protocol.settings.BusConfig` (both ends).

``udp_multicast`` is this package's CAN-over-UDP interface (:mod:`ssi_bridge.base.udp_bus`: no
echo of its own frames, one group on one interface), every other name python-can's own. The
master opens its bus with this as it is (``client/bus.py``); the simulated station wraps it
in its timed wire (``sim/gateway/wire_bus.py``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import can

from ssi_bridge.base.udp_bus import open_udp_bus
from ssi_bridge.exceptions import BusError
from ssi_bridge.protocol.settings import BusConfig

logger = logging.getLogger(__name__)


def open_python_can(config: BusConfig, *, preserve_timestamps: bool = False) -> can.BusABC:
    """A new bus for ``config``; the caller must ``shutdown()`` it.

    ``preserve_timestamps`` (``virtual`` only): receivers get the timestamp the sender set
    (the simulated wire's end of frame) instead of the send time. Raises BusError with the
    interface, channel, bit rate and the reason.
    """
    if config.interface == "udp_multicast":
        try:
            return open_udp_bus(str(config.channel))
        except (can.CanError, OSError) as err:
            raise BusError(f"cannot open CAN bus udp_multicast:{config.channel}: {err}") from err
    kwargs: dict[str, Any] = {"interface": config.interface, "channel": config.channel}
    if config.interface == "virtual":
        kwargs["preserve_timestamps"] = preserve_timestamps
    else:
        kwargs["bitrate"] = config.bitrate
    try:
        bus = can.Bus(**kwargs)
    except (can.CanError, OSError, ValueError, ImportError) as err:
        raise BusError(
            f"cannot open CAN bus {config.interface}:{config.channel} "
            f"at {config.bitrate} bit/s: {err}") from err
    logger.debug("opened %s:%s", config.interface, config.channel)
    return bus


def take_bus(source: BusConfig | can.BusABC | None, owner: str,
             opener: Callable[[BusConfig], can.BusABC] = open_python_can) -> can.BusABC:
    """The bus a master, listener or gateway runs on: ``opener``'s for a config, or the one
    handed over. A handed-over bus belongs to its taker, which shuts it down when it stops;
    so it can be taken once. ``owner`` ("this master", ...) names the taker in the error.

    :param source: a bus configuration, a bus handed over, or None once the handed-over bus
        was taken
    :param opener: opens the bus of a configuration
    :returns: the open bus
    :raises BusError: ``source`` is None (the handed-over bus was taken and shut down), or
        what ``opener`` raises for a bus it cannot open
    """
    if isinstance(source, BusConfig):
        return opener(source)
    if source is None:
        raise BusError(f"{owner}'s bus was handed over and already shut down")
    return source


__all__ = ["open_python_can", "take_bus"]
