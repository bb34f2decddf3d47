"""The driver's own span per cycle, for the benchmark: from the receive timestamp of the frame
that completed a cycle to ``publish()`` of its ``joint_states`` returning.

Off unless the environment variable :data:`SPAN_LOG_ENV` names a file when the node starts
(``bench/node_measure.py`` sets it for the node it measures). Off, the node holds ``None`` and
a cycle pays one ``is None`` test; nothing a user sees changes either way. On, every
published ``joint_states`` adds one record to the file: three little-endian int64, the
receive timestamp (ns, CLOCK_REALTIME) of the newest frame the master had received, the
instant ``publish()`` returned (ns, same clock) and the number of joints in the message,
written in blocks of :data:`BLOCK` records and at exit.

The receive timestamp is the one python-can gives the frame: the kernel's on ``socketcan``
and ``udp_multicast`` (``SO_TIMESTAMPNS``), so the span is what the driver adds on a real bus
from the last TPDO of a cycle in the kernel to the message handed to DDS: the receive
thread's wake-up, the decoding, the cycle's decisions, building and publishing. It is read
from the bus the master receives on (``client/bus.ReceiveWatch.rx_latest``), which keeps it
for the receive path anyway.
"""

from __future__ import annotations

import atexit
import os
import struct
import threading
import time
from collections.abc import Mapping

#: the environment variable naming the file (unset or empty: no probe)
SPAN_LOG_ENV = "SSI_BRIDGE_SPAN_LOG"
#: one record: receive ns, published ns, joints
RECORD = struct.Struct("<qqq")
#: records buffered before a write
BLOCK = 256


class SpanProbe:
    """Appends one record per published cycle to ``path`` (see the module docstring).

    :raises OSError: the file cannot be opened for appending
    """

    def __init__(self, path: str) -> None:
        self.path = path
        self._file = open(path, "ab", buffering=0)  # noqa: SIM115 - closed at exit
        self._buffer = bytearray()
        self._lock = threading.Lock()
        atexit.register(self.flush)

    def published(self, received_s: float, joints: int) -> None:
        """A ``joint_states`` of ``joints`` joints was published just now; the newest frame
        before it was received at ``received_s`` (s, CLOCK_REALTIME)."""
        now = time.time_ns()
        with self._lock:
            self._buffer += RECORD.pack(round(received_s * 1e9), now, joints)
            if len(self._buffer) >= BLOCK * RECORD.size:
                self._write()

    def flush(self) -> None:
        """Write the buffered records."""
        with self._lock:
            self._write()

    def _write(self) -> None:
        """Write and empty the buffer (an error is dropped: the probe never stops a cycle)."""
        data, self._buffer = bytes(self._buffer), bytearray()
        if data:
            try:
                self._file.write(data)
            except (OSError, ValueError):  # ValueError: closed
                pass


def probe_from_env(environ: Mapping[str, str] = os.environ) -> SpanProbe | None:
    """The probe the environment asks for, or None (the default)."""
    path = environ.get(SPAN_LOG_ENV, "")
    return SpanProbe(path) if path else None


def read_spans(path: str) -> list[tuple[int, int, int]]:
    """The records of a span file: (receive ns, published ns, joints) each."""
    with open(path, "rb") as fh:
        data = fh.read()
    usable = len(data) - len(data) % RECORD.size
    return [RECORD.unpack_from(data, i) for i in range(0, usable, RECORD.size)]


__all__ = ["BLOCK", "RECORD", "SPAN_LOG_ENV", "SpanProbe", "probe_from_env", "read_spans"]
