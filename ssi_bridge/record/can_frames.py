"""CAN frames as counted bytes for the fault snapshot's ring, and their candump log.

A frame in the ring is :func:`pack_frame`'s bytes: a 16-byte head (wire time in s as a
double, arbitration id, flags, data length) and the data, so the ring's memory is bytes
(24 bytes of payload for a classic 8-byte frame, plus the ring's fixed entry overhead).
:class:`FrameLog` turns them back into ``can.Message`` and hands them to python-can's
writer for the file's suffix (``can_0.log``: candump/can-utils text, as the session's CAN log
that ``client/sniffer.py`` writes), which ``can.LogReader`` and ``replay.can_log`` read.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from pathlib import Path

import can

#: wire time (s), arbitration id, flags, data length
_HEAD = struct.Struct("<dIBB2x")
EXTENDED, REMOTE, ERROR, FD, BRS, ESI, RX = (1 << k for k in range(7))


def pack_frame(msg: can.Message, wire_time: float) -> bytes:
    """``msg`` at ``wire_time`` (s) as ring bytes."""
    flags = ((EXTENDED if msg.is_extended_id else 0) | (REMOTE if msg.is_remote_frame else 0)
             | (ERROR if msg.is_error_frame else 0) | (FD if msg.is_fd else 0)
             | (BRS if msg.bitrate_switch else 0) | (ESI if msg.error_state_indicator else 0)
             | (RX if msg.is_rx else 0))
    data = bytes(msg.data or b"")
    return _HEAD.pack(wire_time, msg.arbitration_id, flags, msg.dlc) + data


def unpack_frame(raw: bytes) -> can.Message:
    """The ``can.Message`` of :func:`pack_frame`'s bytes (timestamp = the wire time).

    :param raw: the bytes :func:`pack_frame` made
    """
    t, arbitration_id, flags, dlc = _HEAD.unpack_from(raw)
    return can.Message(timestamp=t, arbitration_id=arbitration_id,
                       is_extended_id=bool(flags & EXTENDED),
                       is_remote_frame=bool(flags & REMOTE), is_error_frame=bool(flags & ERROR),
                       is_fd=bool(flags & FD), bitrate_switch=bool(flags & BRS),
                       error_state_indicator=bool(flags & ESI), is_rx=bool(flags & RX),
                       dlc=dlc, data=raw[_HEAD.size:], check=False)


class FrameLog:
    """A CAN log file written from ring bytes (the writer chosen by the suffix).

    :raises OSError: the file cannot be created

    :param path: the log file (``.log``: candump; other suffixes: python-can's writer for it)
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        try:
            self._writer = can.Logger(str(self.path))
        except ValueError as err:  # an unknown suffix
            raise OSError(f"CAN log {self.path}: {err}") from err
        self.frames = 0

    def write(self, frames: Iterable[bytes]) -> None:
        """Append frames (ring bytes), oldest first."""
        for raw in frames:
            self._writer.on_message_received(unpack_frame(raw))
            self.frames += 1

    def close(self) -> None:
        """Flush and close the file."""
        self._writer.stop()
