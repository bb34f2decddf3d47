"""A passive listener on the CAN bus that logs every frame, for sessions replayable at bus level.

It opens its own python-can bus on the configured interface and channel — on the in-process
``virtual`` interface every bus sees what the others send, on socketcan it is one more
socket — so it records both directions (SYNC, SDO, PDO, EMCY, heartbeat) exactly as a
bus analyser would. The file is python-can's format chosen by its suffix (``.log`` is the
candump/can-utils text format, ``.asc`` Vector ASCII, ``.blf`` binary); ``can.LogReader``
and ``can.Player`` read it back. Each frame is logged at its wire time
(``base/timebase.frame_wire_time``; on udp_multicast the sender's end of frame, not the
receive time), so a replay stamps its cycles as the recorded session did.

A write error (disk full, file size limit, I/O error) stops the sniffer at once: it reports
the path and errno through ``on_error``, stops receiving and closes its bus (a virtual bus
nobody reads would queue every frame, ~1 MB/s at 1 kHz), and cuts a text log back to its
last complete line so the file stays readable.
"""

from __future__ import annotations

import logging
import copy
import os
import threading
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import can

from ssi_bridge.exceptions import BusError
from ssi_bridge.client.bus import open_bus
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.base.rate_log import RateLimitedLog
from ssi_bridge.base.rx_guard import ERROR_PAUSE, RECEIVE_ERROR, receive_error_kind
from ssi_bridge.base.timebase import frame_wire_time
from ssi_bridge.base.udp_bus import UndecodableFrame

logger = logging.getLogger(__name__)

#: log formats written line by line, whose torn last line can be cut off
TEXT_SUFFIXES = (".log", ".asc", ".csv", ".txt")
#: bytes read backwards at a time when looking for the last complete line
_TAIL_BLOCK = 64 * 1024


def cut_partial_line(path: Path) -> int:
    """Truncate a text file after its last newline (a write cut short); returns bytes removed.

    :param path: the text file
    """
    with open(path, "r+b") as f:
        size = f.seek(0, os.SEEK_END)
        end = size
        while end > 0:
            start = max(0, end - _TAIL_BLOCK)
            f.seek(start)
            block = f.read(end - start)
            newline = block.rfind(b"\n")
            if newline >= 0:
                keep = start + newline + 1
                break
            end = start
        else:
            keep = 0
        if keep < size:
            f.truncate(keep)
        return size - keep


class _Tee(can.Listener):
    """Counts frames and hands them to the log writer; the notifier's stop() leaves the
    writer open, so frames still queued can be drained into it afterwards. The first write
    error is handed to ``on_fail`` and every later frame is dropped."""

    def __init__(self, writer: can.Listener, on_fail: Callable[[OSError | ValueError], None]
                 ) -> None:
        self.writer = writer
        self.frames = 0
        self.failed = False
        self._on_fail = on_fail
        #: receive errors by kind (``base/rx_guard``: undecodable_frames, receive_errors)
        self.dropped: Counter[str] = Counter()
        self._log = RateLimitedLog(logger)

    def on_message_received(self, msg: can.Message) -> None:
        if self.failed:
            return
        wire_t = frame_wire_time(msg)
        if wire_t != msg.timestamp:
            msg = copy.copy(msg)
            msg.timestamp = wire_t
        try:
            self.writer.on_message_received(msg)
        except (OSError, ValueError) as err:  # ValueError: the file was closed under us
            self.failed = True
            self._on_fail(err)
            return
        self.frames += 1

    def on_error(self, exc: Exception) -> None:
        """A receive error (a datagram that is no CAN frame, an interface gone down): counted
        in :attr:`dropped` by kind, logged at most once per second; logging goes on."""
        kind = receive_error_kind(exc)
        self.dropped[kind] += 1
        self._log.warning(kind, "CAN log: receive error (%s), logging goes on: %s", kind, exc)
        if kind == RECEIVE_ERROR:
            time.sleep(ERROR_PAUSE)

    def stop(self) -> None:
        pass  # the sniffer closes the writer itself, after draining


class CanSniffer:
    """Log all traffic of one bus to ``path`` until :meth:`stop` or a write error.

    ``on_error(reason)`` is called once, from the receiving thread, when writing fails;
    :attr:`error` keeps the reason.

    :param config: the bus to open (its own connection, beside the master's)
    :param path: the candump log file to write
    :param on_error: called once with the reason when writing fails
    :raises BusError: the bus cannot be opened
    """

    def __init__(self, config: BusConfig, path: Path,
                 on_error: Callable[[str], None] | None = None) -> None:
        self.path = Path(path)
        self.error = ""
        self._on_error = on_error
        self._lock = threading.Lock()
        self._closed = False
        self._bus = open_bus(config)
        try:
            self._writer = can.Logger(str(self.path))
        except (OSError, ValueError) as err:
            self._bus.shutdown()
            raise BusError(f"cannot write CAN log {self.path}: {err}") from err
        self._tee = _Tee(self._writer, self._fail)
        self._notifier = can.Notifier(self._bus, [self._tee], timeout=0.1)
        logger.info("logging CAN traffic of %s:%s to %s", config.interface, config.channel,
                    self.path)

    @property
    def frames(self) -> int:
        """Frames logged so far."""
        return self._tee.frames

    @property
    def dropped(self) -> dict[str, int]:
        """Receive errors by kind (undecodable_frames, receive_errors); logging went on."""
        return dict(self._tee.dropped)

    @property
    def failed(self) -> bool:
        """True once a write error stopped the log."""
        return self._tee.failed

    def stop(self) -> int:
        """Stop listening, close the file and the bus; returns the frames logged.

        Frames already received but not yet taken by the notifier thread are drained and
        logged too: everything on the bus before ``stop()`` ends up in the file. Safe after
        a write error (the file was closed then) and when called twice.
        """
        with self._lock:
            if self._closed:
                return self.frames
            self._closed = True
            self._notifier.stop()
            if not self._tee.failed:
                self._drain()
            self._close_file()
            self._bus.shutdown()
        return self.frames

    def _drain(self) -> None:
        """Log the frames still queued on the bus (a datagram that is no frame is skipped)."""
        while not self._tee.failed:
            try:
                msg = self._bus.recv(0)
            except UndecodableFrame as err:
                self._tee.on_error(err)
                continue
            except can.CanError as err:
                logger.warning("CAN log %s: draining the bus failed: %s", self.path, err)
                return
            if msg is None:
                return
            self._tee.on_message_received(msg)

    def _fail(self, err: OSError | ValueError) -> None:
        """First write error: say why (path, errno), then stop in the background."""
        errno = getattr(err, "errno", None)
        why = getattr(err, "strerror", None) or str(err)
        self.error = (f"writing CAN log {self.path} failed: {why}"
                      + (f" (errno {errno})" if errno else "") + "; CAN log stopped")
        logger.error("%s", self.error)
        if self._on_error is not None:
            try:
                self._on_error(self.error)
            except Exception:  # noqa: BLE001 - the receiving thread must end quietly
                logger.exception("CAN log error callback failed")
        # notifier.stop() joins this (receiving) thread: do it from another one
        threading.Thread(target=self.stop, name="can-log-stop", daemon=True).start()

    def _close_file(self) -> None:
        """Close the writer (its buffer may fail to flush after an error), then make sure
        the file ends with a complete line."""
        try:
            self._writer.stop()
        except (OSError, ValueError) as err:
            if not self._tee.failed:
                self._tee.failed = True
                self.error = f"closing CAN log {self.path} failed: {err}; CAN log stopped"
                logger.error("%s", self.error)
                if self._on_error is not None:
                    self._on_error(self.error)
        if self._tee.failed and self.path.suffix.lower() in TEXT_SUFFIXES:
            try:
                removed = cut_partial_line(self.path)
            except OSError as err:
                logger.error("CAN log %s: cannot cut the torn last line: %s", self.path, err)
                return
            if removed:
                logger.info("CAN log %s: cut %d bytes of a torn last line", self.path, removed)
            if self.path.suffix.lower() == ".log":
                self._tee.frames = self._count_lines()

    def _count_lines(self) -> int:
        """Frames in a candump log cut after an error: its ``(timestamp) ...`` lines."""
        try:
            with open(self.path, "rb") as f:
                return sum(1 for line in f if line.startswith(b"("))
        except OSError:
            return self._tee.frames
