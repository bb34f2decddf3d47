"""Wait for a CANopen node's boot-up message (CiA 301: COB-ID 0x700 + id, one byte 0x00).

A master that starts a station (the simulated one as a child process) listens before the
station starts and waits, bounded, for the boot-up, so configuration begins only once the
station is on the bus; a heartbeat of the node counts as well (it was already up).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import can

from ssi_bridge.exceptions import GatewayUnavailable

logger = logging.getLogger(__name__)

NMT_ERROR_CONTROL = 0x700


class BootWatch:
    """Listens on an open bus from construction on; :meth:`wait` returns at the boot-up.

    :param bus: the open bus (receiving starts now, so no boot-up is missed)
    :param node_id: the station's node id
    """

    def __init__(self, bus: can.BusABC, node_id: int) -> None:
        self.bus = bus
        self.node_id = node_id

    def wait(self, timeout: float, alive: Callable[[], str | None] = lambda: None) -> float:
        """Seconds until node ``node_id`` sent boot-up or heartbeat; GatewayUnavailable if not.

        ``alive`` returns why the station cannot come any more (its process ended), or None;
        it is checked between frames so such a station fails at once, not at the timeout.
        """
        start = time.monotonic()
        deadline = start + timeout
        cob = NMT_ERROR_CONTROL + self.node_id
        while True:
            left = deadline - time.monotonic()
            gone = alive()
            if gone:
                raise GatewayUnavailable(gone)
            if left <= 0:
                raise GatewayUnavailable(
                    f"no boot-up from node {self.node_id} within {timeout:g} s")
            try:
                msg = self.bus.recv(min(left, 0.1))
            except can.CanOperationError as err:  # e.g. a datagram that is no CAN frame
                logger.debug("waiting for boot-up of node %d: %s", self.node_id, err)
                continue
            if msg is not None and msg.arbitration_id == cob and not msg.is_remote_frame \
                    and len(msg.data) == 1:
                return time.monotonic() - start
