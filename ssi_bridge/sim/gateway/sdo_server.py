"""The station's SDO server: canopen's, answering only while the NMT state allows, under the
station lock, and refusing an SDO segment that belongs to no transfer.

canopen's ``SdoServer`` keeps the buffer of the last segmented transfer and never clears it: a
download or upload segment with no transfer running raised inside it (``'NoneType' object has
no attribute 'extend'``, logged with a traceback), and one after a finished segmented download
appended to the old buffer and wrote the object again. :class:`StationSdo` follows each
transfer from the frames it answers (CiA 301 SDO protocol: initiate, segments, the last one
flagged, or an abort) and answers a segment outside one with the abort 0x05040001 "command
specifier not valid or unknown", reported as a malformed frame (``base/rx_guard``) instead of
passing it on. A request with command specifier 7 (none of CiA 301's) gets the same abort and
report (canopen's own abort of it raised while no transfer had set its multiplexer yet); a
block download (optional in CiA 301, not served) the abort alone, without the ERROR line
canopen logs for it. Frames of another length than 8 bytes never get here: the station's
listener drops them (``protocol/frame_rules.py``).
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

from canopen.sdo.server import SdoServer

from ssi_bridge.protocol.aborts import SdoAbort

#: CiA 301 SDO command specifiers (bits 7..5 of byte 0): client requests ...
CCS_SEGMENT_DOWNLOAD, CCS_SEGMENT_UPLOAD, CCS_ABORT = 0x00, 0x60, 0x80
CCS_BLOCK_DOWNLOAD, CCS_NONE = 0xC0, 0xE0
#: ... and server responses
SCS_SEGMENT_UPLOAD, SCS_SEGMENT_DOWNLOAD, SCS_INITIATE_UPLOAD = 0x00, 0x20, 0x40
SCS_INITIATE_DOWNLOAD, SCS_ABORT = 0x60, 0x80
#: byte 0 flags: e (expedited) of an initiate, c (no more segments) of a segment
EXPEDITED, LAST_SEGMENT = 0x02, 0x01
#: the abort frame: specifier, index, subindex, abort code (CiA 301, little endian)
ABORT_STRUCT = struct.Struct("<BHBL")
#: ``report(can_id, data, why)``: a frame the server refused as malformed
Report = Callable[[int, bytes, str], None]


class StationSdo(SdoServer):
    """canopen's SDO server for station ``node``, with the transfer it serves followed.

    :param node: the station's ``LocalNode``; it has ``lock`` (the station lock) and ``nmt``
    :param states: NMT states in which SDO is served (CiA 301: not in STOPPED)
    """

    def __init__(self, node: Any, states: tuple[str, ...]) -> None:
        # canopen's SdoServer is unannotated (super() calls escape untyped_calls_exclude)
        super().__init__(0x600 + node.id, 0x580 + node.id, node)  # type: ignore[no-untyped-call]
        self._station = node
        self._states = states
        #: the segments the running transfer takes (CCS_SEGMENT_*), None when none runs
        self.segments: int | None = None
        self._request = 0  # byte 0 of the request being answered
        #: where refused frames are reported (set by the gateway to its listener's)
        self.report: Report | None = None

    def on_request(self, can_id: int, data: bytearray, timestamp: float) -> None:
        """Serve one 8-byte request (network thread) in PRE-OPERATIONAL/OPERATIONAL.

        :param can_id: 0x600 + the node id
        :param data: the request's 8 bytes
        :param timestamp: its wire time (s)
        """
        with self._station.lock:
            if self._station.nmt.state not in self._states:
                return
            command = data[0] if data else 0
            ccs = command & 0xE0
            if ccs in (CCS_SEGMENT_DOWNLOAD, CCS_SEGMENT_UPLOAD) and ccs != self.segments:
                if self.report is not None:
                    self.report(can_id, bytes(data), "an SDO segment outside a transfer "
                                "(CiA 301: answered with abort 0x05040001)")
                self.send_response(ABORT_STRUCT.pack(SCS_ABORT, 0, 0,
                                                     SdoAbort.INVALID_COMMAND))
                return
            if ccs in (CCS_BLOCK_DOWNLOAD, CCS_NONE):
                # block download is optional (CiA 301) and not served; 7 is no specifier
                # at all: both aborted with the request's multiplexer
                if ccs == CCS_NONE and self.report is not None:
                    self.report(can_id, bytes(data), "no SDO command (specifier 7; CiA 301: "
                                "answered with abort 0x05040001)")
                _, index, subindex = struct.unpack_from("<BHB", data)
                self.send_response(ABORT_STRUCT.pack(SCS_ABORT, index, subindex,
                                                     SdoAbort.INVALID_COMMAND))
                return
            if ccs == CCS_ABORT:
                self.segments = None
            self._request = command
            super().on_request(can_id, data, timestamp)  # type: ignore[no-untyped-call]

    def send_response(self, response: bytes | bytearray) -> None:
        """Send the answer and note whether a segmented transfer runs on after it.

        :param response: the 8 bytes of the answer
        """
        scs = response[0] & 0xE0
        if scs == SCS_ABORT:
            self.segments = None
        elif scs == SCS_INITIATE_UPLOAD:
            self.segments = None if response[0] & EXPEDITED else CCS_SEGMENT_UPLOAD
        elif scs == SCS_INITIATE_DOWNLOAD:
            self.segments = None if self._request & EXPEDITED else CCS_SEGMENT_DOWNLOAD
        elif scs == SCS_SEGMENT_DOWNLOAD and self._request & LAST_SEGMENT:
            self.segments = None
        elif scs == SCS_SEGMENT_UPLOAD and response[0] & LAST_SEGMENT:
            self.segments = None
        super().send_response(response)  # type: ignore[no-untyped-call]


__all__ = ["StationSdo"]
