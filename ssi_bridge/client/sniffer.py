"""A passive listener on the CAN bus that logs every frame, for sessions replayable at bus level.

It opens its own python-can bus on the configured interface and channel — on the in-process
``virtual`` interface every bus sees what the others send, on socketcan it is one more
socket — so it records both directions (SYNC, SDO, PDO, EMCY, heartbeat) exactly as a
bus analyser would. The file is python-can's format chosen by its suffix (``.log`` is the
candump/can-utils text format, ``.asc`` Vector ASCII, ``.blf`` binary); ``can.LogReader``
and ``can.Player`` read it back.
"""

from __future__ import annotations

import logging
from pathlib import Path

import can

from ssi_bridge.exceptions import BusError
from ssi_bridge.gateway.bus import BusConfig, open_bus

logger = logging.getLogger(__name__)


class _Tee(can.Listener):
    """Counts frames and hands them to the log writer; the notifier's stop() leaves the
    writer open, so frames still queued can be drained into it afterwards."""

    def __init__(self, writer: can.Listener) -> None:
        self.writer = writer
        self.frames = 0

    def on_message_received(self, msg: can.Message) -> None:
        self.writer.on_message_received(msg)
        self.frames += 1

    def stop(self) -> None:
        pass  # the sniffer closes the writer itself, after draining


class CanSniffer:
    """Log all traffic of one bus to ``path`` until :meth:`stop`."""

    def __init__(self, config: BusConfig, path: Path) -> None:
        self.path = Path(path)
        self._bus = open_bus(config)
        try:
            self._writer = can.Logger(str(self.path))
        except (OSError, ValueError) as err:
            self._bus.shutdown()
            raise BusError(f"cannot write CAN log {self.path}: {err}") from err
        self._tee = _Tee(self._writer)
        self._notifier = can.Notifier(self._bus, [self._tee], timeout=0.1)
        logger.info("logging CAN traffic of %s:%s to %s", config.interface, config.channel,
                    self.path)

    @property
    def frames(self) -> int:
        """Frames logged so far."""
        return self._tee.frames

    def stop(self) -> int:
        """Stop listening, close the file and the bus; returns the frames logged.

        Frames already received but not yet taken by the notifier thread are drained and
        logged too: everything on the bus before ``stop()`` ends up in the file.
        """
        self._notifier.stop()
        while (msg := self._bus.recv(0)) is not None:
            self._tee.on_message_received(msg)
        self._writer.stop()
        self._bus.shutdown()
        return self.frames
