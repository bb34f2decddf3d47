"""python-can's udp_multicast wire format, read and written in one step per frame.

Every CAN frame on a udp_multicast group is one msgpack map of the ``can.Message`` fields
(python-can's ``pack_message``/``unpack_message``). The master's receive thread handles every
frame of the bus, so the frames it sees all the time (classic data, remote and error frames)
take a short path here: :func:`unpack_frame` turns the datagram into one :class:`UdpFrame`,
read by position when it is laid out as a frame of the same COB-ID, kind and length seen
before, else straight from the unpacked map, with python-can's checks
(``Message(check=True)``) spelled out for these frames; :func:`pack_frame` writes the map's
bytes from per-frame parts. Whatever
else a datagram holds (a CAN FD frame, a field of another type, a map of other keys, no
msgpack at all) goes through python-can's own functions, so the result, or the error, is
always python-can's (``test/base/test_udp_frames.py`` compares both on random frames).
"""

from __future__ import annotations

import math
import struct

import can
import msgpack  # type: ignore[import-untyped]  # ships no type hints

from ssi_bridge.base.can_compat import pack_message, unpack_message

#: a sender's timestamp is taken as the frame's wire time only this close to its receive time
#: (s): a python-can tool may send a frame with no stamp (0) or replay a logged one
WIRE_TIME_PLAUSIBLE = 1.0

_new_message = can.Message.__new__
#: the fields of a can.Message (its __slots__ minus the weak-reference slot)
_FIELDS = tuple(n for n in can.Message.__slots__ if n != "__weakref__")
_unpackb = msgpack.unpackb


def _packb(value: object) -> bytes:
    """msgpack of ``value`` as python-can packs (``use_bin_type=True``)."""
    return bytes(msgpack.packb(value, use_bin_type=True))


_INF = math.inf
#: the keys python-can packs, in its order (``pack_message``)
_KEYS = ("timestamp", "arbitration_id", "is_extended_id", "is_remote_frame", "is_error_frame",
         "channel", "dlc", "data", "is_fd", "bitrate_switch", "error_state_indicator")
#: identifiers below this are standard ones; extended ones below :data:`_EXTENDED_END`
_STANDARD_END, _EXTENDED_END = 0x800, 0x20000000
#: classic CAN's longest payload
_CLASSIC_BYTES = 8


class UndecodableFrame(can.CanOperationError):
    """A datagram on the group that is not a CAN frame (the bus drops it; the next goes on)."""


class UdpFrame(can.Message):
    """A frame received on udp_multicast: the kernel's receive ``timestamp`` and the sender's
    :attr:`wire_time` (its end on the wire, the instant every receiver shares)."""

    __slots__ = ("wire_time",)
    wire_time: float

    @classmethod
    def of(cls, msg: can.Message, timestamp: float, wire_time: float) -> UdpFrame:
        """A copy of ``msg`` (fields and a new payload) with these two times."""
        frame = _new_message(cls)
        for name in _FIELDS:
            setattr(frame, name, getattr(msg, name))
        frame.data = bytearray(msg.data)
        frame.timestamp = timestamp
        frame.wire_time = wire_time
        return frame

    def __copy__(self) -> UdpFrame:
        return UdpFrame.of(self, self.timestamp, self.wire_time)

    def __deepcopy__(self, memo: dict[int, object] | None) -> UdpFrame:
        return UdpFrame.of(self, self.timestamp, self.wire_time)


def wire_time_of(sent: float, received: float) -> float:
    """The wire time of a frame the sender stamped ``sent`` and the kernel received at
    ``received``: ``sent`` when it is a plausible stamp (within :data:`WIRE_TIME_PLAUSIBLE`),
    else ``received``."""
    if sent > 0 and abs(received - sent) <= WIRE_TIME_PLAUSIBLE:
        return sent
    return received


def _classic(d: dict[str, object]) -> UdpFrame | None:
    """The classic frame (not FD) map ``d`` holds when every field has the type python-can
    packs and passes ``Message._check``; None for anything else (the caller asks python-can).
    Its ``timestamp`` is the sender's (the caller sets both times)."""
    try:
        ts, aid, ext, rtr, err, channel, dlc, payload, fd, brs, esi = (
            d["timestamp"], d["arbitration_id"], d["is_extended_id"], d["is_remote_frame"],
            d["is_error_frame"], d["channel"], d["dlc"], d["data"], d["is_fd"],
            d["bitrate_switch"], d["error_state_indicator"])
    except KeyError:
        return None
    if (fd is not False or brs is not False or esi is not False or type(ts) is not float
            or not 0.0 <= ts < _INF or type(aid) is not int or type(dlc) is not int
            or type(payload) is not bytes or type(ext) is not bool or type(rtr) is not bool
            or type(err) is not bool or not 0 <= aid < (_EXTENDED_END if ext else _STANDARD_END)
            or not 0 <= dlc <= _CLASSIC_BYTES):
        return None
    if rtr:
        if err:
            return None  # python-can: "a message cannot be a remote and an error frame"
        data = bytearray()  # python-can drops a remote frame's payload
    elif dlc == len(payload):
        data = bytearray(payload)
    else:
        return None
    return _classic_frame(ts, aid, ext, rtr, err, channel, dlc, data)


def _classic_frame(ts: float, aid: int, ext: bool, rtr: bool, err: bool, channel: object,
                   dlc: int, data: bytearray) -> UdpFrame:
    """A received classic (not FD) frame of these fields, built without ``Message.__init__``'s
    checks (the caller made them)."""
    frame = _new_message(UdpFrame)
    frame.timestamp = ts
    frame.arbitration_id = aid
    frame.is_extended_id = ext
    frame.is_remote_frame = rtr
    frame.is_error_frame = err
    frame.channel = channel  # type: ignore[assignment]  # what python-can's map held
    frame.dlc = dlc
    frame.data = data
    frame.is_fd = False
    frame.is_rx = True
    frame.bitrate_switch = False
    frame.error_state_indicator = False
    return frame


def unpack_frame(data: bytes, received: float) -> UdpFrame:
    """A python-can udp_multicast datagram as a :class:`UdpFrame` received at ``received``.

    Equal in every ``can.Message`` field to python-can's ``unpack_message(data,
    check=True)`` with ``received`` as its timestamp; :attr:`UdpFrame.wire_time` is the
    sender's stamp where plausible (:func:`wire_time_of`).

    :raises Exception: what python-can's ``unpack_message`` raises for ``data``
    """
    frame = _laid_out(data)
    if frame is None:
        try:
            d = _unpackb(data, raw=False)
        except Exception:  # noqa: BLE001 - python-can's unpack below raises it again, as its own
            d = None
        frame = _classic(d) if type(d) is dict and len(d) == len(_KEYS) else None
        if frame is None:
            sent = unpack_message(data, check=True)  # its timestamp: the sender's
            return UdpFrame.of(sent, received, wire_time_of(sent.timestamp, received))
        _learn(data, frame, len(d["data"]))
    sent_at = frame.timestamp
    frame.timestamp = received
    frame.wire_time = (sent_at if sent_at > 0 and abs(received - sent_at) <= WIRE_TIME_PLAUSIBLE
                       else received)
    return frame


_key = {name: _packb(name) for name in _KEYS}
_TRUE, _FALSE, _NONE = _packb(True), _packb(False), _packb(None)
#: map header and first key, then the float64 marker: python-can's timestamp is a float
_HEAD = _packb({k: None for k in _KEYS})[:1] + _key["timestamp"] + _packb(0.5)[:1]
_F64 = struct.Struct(">d").pack
_ID_KEY = _key["arbitration_id"]
#: msgpack of 0..0x7FF (identifiers and lengths): the library's own encoding, looked up
_UINTS = [_packb(i) for i in range(_STANDARD_END)]


def _flags(*names: str, then: bytes = b"") -> list[bytes]:
    """The bytes of boolean fields ``names`` (and ``then``) for each of their 2^n values,
    indexed by the values as bits (first name highest)."""
    out = []
    for bits in range(1 << len(names)):
        parts = []
        for i, name in enumerate(names):
            on = bits >> (len(names) - 1 - i) & 1
            parts += [_key[name], _TRUE if on else _FALSE]
        out.append(b"".join(parts) + then)
    return out


#: ext/rtr/err, then channel None and the dlc key; fd/brs/esi at the end
_MIDDLE = _flags("is_extended_id", "is_remote_frame", "is_error_frame",
                 then=_key["channel"] + _NONE + _key["dlc"])
_TAIL = _flags("is_fd", "bitrate_switch", "error_state_indicator")
#: the data key and the bin 8 marker (payloads below 256 bytes)
_DATA_BIN8 = _key["data"] + _packb(b"")[:1]
_BIN8_MAX = 255
#: a bin 8 length byte
_LENGTHS = [bytes((n,)) for n in range(_BIN8_MAX + 1)]


def _uint(value: int) -> bytes:
    return _UINTS[value] if 0 <= value < _STANDARD_END else _packb(value)


def pack_frame(msg: can.Message) -> bytes:
    """``msg`` as python-can's udp_multicast datagram: the same bytes as its
    ``pack_message(msg)`` (which packs any frame this does not: a channel, a field of
    another type, a payload of 256 bytes or more).

    :raises Exception: what python-can's ``pack_message`` raises for ``msg``
    """
    ts, aid, dlc, data = msg.timestamp, msg.arbitration_id, msg.dlc, msg.data
    ext, rtr, err = msg.is_extended_id, msg.is_remote_frame, msg.is_error_frame
    fd, brs, esi = msg.is_fd, msg.bitrate_switch, msg.error_state_indicator
    if (msg.channel is not None or type(ts) is not float or type(aid) is not int
            or aid < 0 or type(dlc) is not int or dlc < 0
            or not isinstance(data, (bytes, bytearray)) or len(data) > _BIN8_MAX
            or type(ext) is not bool or type(rtr) is not bool or type(err) is not bool
            or type(fd) is not bool or type(brs) is not bool or type(esi) is not bool):
        return pack_message(msg)
    return b"".join((_HEAD, _F64(ts), _ID_KEY, _uint(aid), _MIDDLE[ext << 2 | rtr << 1 | err],
                     _uint(dlc), _DATA_BIN8, _LENGTHS[len(data)], data,
                     _TAIL[fd << 2 | brs << 1 | esi]))


# -- reading a datagram by its layout -----------------------------------------------------------
# A classic frame packed by python-can (or pack_frame) is: map header, "timestamp" key, float64
# marker (_HEAD); the float64; the identifier's key and value; flags, channel None, dlc key
# (_MIDDLE); the dlc; data key and bin 8 marker; the payload's length; the payload; the FD flags
# (_TAIL[0]: all False). Everything from the identifier's key to the payload's length is the
# same for every frame of one COB-ID, kind and length: its "layout", learnt from the first
# such frame python-can's decoding took, then read by position. msgpack's decoding of a
# byte string is unique, so a datagram that matches a layout decodes to its fields exactly.

_TS_AT = len(_HEAD)
_ID_AT = _TS_AT + 8
_AID_AT = _ID_AT + len(_ID_KEY)
#: bytes of a msgpack unsigned integer by its first byte (positive fixint, uint 8/16/32)
_UINT_BYTES = {**{b: 1 for b in range(0x80)}, 0xCC: 2, 0xCD: 3, 0xCE: 5}
#: from the identifier's end to the payload: _MIDDLE, the dlc (0-8: one byte), the data key
#: and bin 8 marker, the payload's length
_TO_PAYLOAD = len(_MIDDLE[0]) + 1 + len(_DATA_BIN8) + 1
_CLASSIC_TAIL = _TAIL[0]
_F64_AT = struct.Struct(">d").unpack_from
#: layout bytes -> (identifier, extended, remote, error, dlc, payload bytes in the datagram)
_LAYOUTS: dict[bytes, tuple[int, bool, bool, bool, int, int]] = {}
#: layouts kept (a bus has a few dozen: COB-IDs x lengths); beyond, the others are decoded
LAYOUTS_KEPT = 4096


def _laid_out(data: bytes) -> UdpFrame | None:
    """The frame of ``data`` when it has a layout seen before (its timestamp the sender's),
    else None."""
    if len(data) <= _AID_AT or not data.startswith(_HEAD):
        return None
    width = _UINT_BYTES.get(data[_AID_AT])
    if width is None:
        return None
    end = _AID_AT + width + _TO_PAYLOAD
    layout = _LAYOUTS.get(data[_ID_AT:end])
    if layout is None:
        return None
    aid, ext, rtr, err, dlc, n = layout
    if len(data) != end + n + len(_CLASSIC_TAIL) or not data.endswith(_CLASSIC_TAIL):
        return None
    ts = _F64_AT(data, _TS_AT)[0]
    if not 0.0 <= ts < _INF:
        return None
    return _classic_frame(ts, aid, ext, rtr, err, None, dlc,
                          bytearray() if rtr else bytearray(data[end:end + n]))


def _learn(data: bytes, frame: UdpFrame, n: int) -> None:
    """Keep the layout of ``data``, which decoded to ``frame`` (``n`` payload bytes in the
    datagram), when it is laid out as python-can packs a frame (and room is left)."""
    if frame.channel is not None or len(_LAYOUTS) >= LAYOUTS_KEPT or len(data) <= _AID_AT:
        return
    layout = b"".join((_ID_KEY, _uint(frame.arbitration_id), _MIDDLE[
        frame.is_extended_id << 2 | frame.is_remote_frame << 1 | frame.is_error_frame],
        _uint(frame.dlc), _DATA_BIN8, _LENGTHS[n]))
    if (len(layout) == _AID_AT - _ID_AT + _UINT_BYTES.get(data[_AID_AT], 0) + _TO_PAYLOAD
            and data.startswith(_HEAD) and data.startswith(layout, _ID_AT)
            and len(data) == _ID_AT + len(layout) + n + len(_CLASSIC_TAIL)
            and data.endswith(_CLASSIC_TAIL)):
        _LAYOUTS[layout] = (frame.arbitration_id, frame.is_extended_id, frame.is_remote_frame,
                            frame.is_error_frame, frame.dlc, n)


__all__ = ["LAYOUTS_KEPT", "UdpFrame", "UndecodableFrame", "WIRE_TIME_PLAUSIBLE", "pack_frame", "unpack_frame",
           "wire_time_of"]
