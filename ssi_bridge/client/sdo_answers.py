"""Which SDO server frame answers the client's current request (CiA 301 §7.2.4.3).

An SDO channel carries no sequence number: a server that stalled and resumed answers the
requests it had queued, and the answer to a request that already timed out arrives while the
client waits for the answer to the next one. canopen's client takes the first frame on the
response COB-ID; a late answer to another object then failed the current transfer ("Node
returned a value for 0x1017:00 instead"). :class:`SdoAnswers` tells the answer to the current
request from a stale one by what CiA 301 puts in the frame:

* byte 0, bits 7-5: the command specifier. Each client request has one server response
  (initiate download 1 -> 3, initiate upload 2 -> 2, download segment 0 -> 1, upload segment
  3 -> 0) or an abort (4);
* bytes 1-3 of an initiate response and of an abort: the multiplexer (index little endian,
  then sub-index) of the object the transfer is about;
* bit 4 of a segment response: the toggle bit of the segment request it answers.

A frame whose specifier, multiplexer or toggle bit is not the current request's is stale. Two
answers of one kind to one object cannot be told apart on the wire (a repeated request's
second answer to the same object): the first taken is as good as the other, and the other is
then stale for the next request. Block transfers (specifiers 5 and 6) are not checked: the
master does not use them.
"""

from __future__ import annotations

import struct

#: command specifier of byte 0 (bits 7-5); client side
CCS_DOWNLOAD_SEGMENT, CCS_INITIATE_DOWNLOAD, CCS_INITIATE_UPLOAD, CCS_UPLOAD_SEGMENT = 0, 1, 2, 3
#: server side
SCS_UPLOAD_SEGMENT, SCS_DOWNLOAD_SEGMENT, SCS_INITIATE_UPLOAD, SCS_INITIATE_DOWNLOAD = 0, 1, 2, 3
#: abort transfer, either side
CS_ABORT = 4
#: the toggle bit of a segment request and its response
TOGGLE = 0x10
#: the server response each client request is answered by
RESPONSE_TO = {CCS_INITIATE_DOWNLOAD: SCS_INITIATE_DOWNLOAD,
               CCS_INITIATE_UPLOAD: SCS_INITIATE_UPLOAD,
               CCS_DOWNLOAD_SEGMENT: SCS_DOWNLOAD_SEGMENT,
               CCS_UPLOAD_SEGMENT: SCS_UPLOAD_SEGMENT}
_SERVER_NAMES = {SCS_UPLOAD_SEGMENT: "upload segment",
                 SCS_DOWNLOAD_SEGMENT: "download segment",
                 SCS_INITIATE_UPLOAD: "initiate upload",
                 SCS_INITIATE_DOWNLOAD: "initiate download",
                 CS_ABORT: "abort", 5: "block download", 6: "block upload", 7: "unknown"}
_MULTIPLEXER = struct.Struct("<HB")


def multiplexer(frame: bytes) -> tuple[int, int]:
    """(index, sub-index) of bytes 1-3 of an SDO frame (raises ValueError when shorter)."""
    if len(frame) < 4:
        raise ValueError(f"an SDO frame of {len(frame)} bytes carries no multiplexer")
    index, subindex = _MULTIPLEXER.unpack_from(frame, 1)
    return index, subindex


def _where(mux: tuple[int, int] | None) -> str:
    return "an unknown object" if mux is None else f"0x{mux[0]:04X}:{mux[1]:02X}"


class SdoAnswers:
    """The current request of one SDO client and whether a server frame answers it.

    Call :meth:`sent` with every request before its answer is awaited (a repeated request
    changes nothing) and :meth:`why_stale` with every frame received on the response COB-ID.
    Used by one transfer at a time (the SDO client serialises them); not thread-safe.
    """

    def __init__(self) -> None:
        #: the last request sent (None: none yet, nothing is checked)
        self.request: bytes | None = None
        #: multiplexer of the transfer in progress (its initiate request), for the segments
        self.transfer: tuple[int, int] | None = None

    def sent(self, request: bytes) -> None:
        """``request`` (8 bytes) is the one the next answer must answer."""
        self.request = bytes(request)
        if request and request[0] >> 5 in (CCS_INITIATE_DOWNLOAD, CCS_INITIATE_UPLOAD):
            self.transfer = multiplexer(request)

    def why_stale(self, response: bytes) -> str | None:
        """None when ``response`` may answer the current request; else why it cannot."""
        if self.request is None:  # nothing sent yet: nothing to check against
            return None
        if not response:
            return "it is empty"
        ccs, scs = self.request[0] >> 5, response[0] >> 5
        due = RESPONSE_TO.get(ccs)
        if due is None:  # block transfer or the client's own abort: not checked
            return None
        if len(response) < 4 and scs in (CS_ABORT, SCS_INITIATE_UPLOAD, SCS_INITIATE_DOWNLOAD):
            return f"its {_SERVER_NAMES[scs]} response has only {len(response)} bytes"
        if scs == CS_ABORT:
            wanted = self.transfer if due in (SCS_UPLOAD_SEGMENT, SCS_DOWNLOAD_SEGMENT) \
                else multiplexer(self.request)
            got = multiplexer(response)
            if wanted is not None and got != wanted:
                return f"it aborts {_where(got)}, the current transfer is {_where(wanted)}"
            return None
        if scs != due:
            return (f"it is an '{_SERVER_NAMES[scs]}' response where '{_SERVER_NAMES[due]}' "
                    f"is due")
        if due in (SCS_INITIATE_UPLOAD, SCS_INITIATE_DOWNLOAD):
            got, wanted = multiplexer(response), multiplexer(self.request)
            if got != wanted:
                return f"it answers {_where(got)}, the current request is for {_where(wanted)}"
            return None
        if response[0] & TOGGLE != self.request[0] & TOGGLE:
            return (f"its toggle bit {int(bool(response[0] & TOGGLE))} answers the previous "
                    f"segment of {_where(self.transfer)}")
        return None


__all__ = ["SdoAnswers", "multiplexer"]
