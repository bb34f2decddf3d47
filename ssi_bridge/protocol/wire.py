"""How long a CAN 2.0A frame occupies the wire, and what a SYNC cycle of the station costs.

A classical base frame (ISO 11898-1) is SOF, 11-bit identifier, RTR, IDE, r0, 4-bit DLC,
0-8 data bytes, 15-bit CRC (polynomial 0x4599 over SOF..data), then CRC delimiter, ACK slot,
ACK delimiter, 7 EOF bits and the 3-bit intermission (IFS). SOF..CRC is bit-stuffed: after
five equal bits the transmitter inserts one of the opposite level (and the stuff bit counts
for the next run). :func:`frame_bits` counts a real frame's bits from its actual content;
:func:`worst_frame_bits` is the classical upper bound, used where the content is not known
(the rate table and the start-up check).

One SYNC cycle of the bridge (``docs/canopen.md``) is SYNC (no data) + one 8-byte process input
image TPDO per slot + the encoder default PDOs carrying 0x6820 of slot pairs (8 bytes, 4 for an
odd last slot). :func:`max_cycle_rate` leaves :data:`SDO_RESERVE_FRAMES` 8-byte frames per
cycle free for register traffic (an SDO request and its response, and the RPDO of a handshake
step), so a register access never pushes the cycle's own frames past the next SYNC.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

#: bits after the CRC that are never stuffed: CRC delimiter, ACK slot, ACK delimiter, EOF, IFS
TAIL_BITS = 1 + 1 + 1 + 7 + 3
#: 8-byte frames per cycle kept free for register traffic (SDO request + response, one RPDO)
SDO_RESERVE_FRAMES = 3
#: bit rates of the rate table (bit/s)
TABLE_BITRATES = (125_000, 250_000, 500_000, 1_000_000)
_CRC15_POLY = 0x4599


def _bits(value: int, width: int) -> list[int]:
    return [(value >> i) & 1 for i in range(width - 1, -1, -1)]


def crc15(bits: Iterable[int]) -> int:
    """The CAN CRC-15 of a bit sequence (ISO 11898-1, polynomial 0x4599, initial 0).

    :param bits: the bits from SOF to the end of the data field, one int (0/1) each
    """
    crc = 0
    for bit in bits:
        nxt = bit ^ ((crc >> 14) & 1)
        crc = (crc << 1) & 0x7FFF
        if nxt:
            crc ^= _CRC15_POLY
    return crc


def stuff_count(bits: Sequence[int]) -> int:
    """Stuff bits a transmitter inserts into ``bits`` (one after every 5 equal levels)."""
    count, run, last = 0, 0, -1
    for bit in bits:
        if bit == last:
            run += 1
        else:
            last, run = bit, 1
        if run == 5:
            count += 1
            last, run = 1 - bit, 1  # the stuff bit starts the next run
    return count


def _crc15_of_int(value: int, width: int) -> int:
    """:func:`crc15` of the ``width`` bits of ``value``, most significant first, without
    making a list of them."""
    crc = 0
    for i in range(width - 1, -1, -1):
        nxt = ((value >> i) & 1) ^ ((crc >> 14) & 1)
        crc = (crc << 1) & 0x7FFF
        if nxt:
            crc ^= _CRC15_POLY
    return crc


#: the CRC-15 of each byte value, for the byte-wise step of :func:`frame_bits`
_CRC_TABLE = [_crc15_of_int(byte, 8) for byte in range(256)]


def _step(last: int, run: int, bit: int) -> tuple[int, int, int]:
    """One transmitted bit: (stuff bits inserted, new last level, new run length)."""
    run = run + 1 if bit == last else 1
    if run == 5:
        return 1, 1 - bit, 1
    return 0, bit, run


#: the stuffing states (last level, run length; -1: no bit yet) and their numbers
_STATES = [(last, run) for last in (-1, 0, 1) for run in range(5)]
_STATE_NO = {state: i for i, state in enumerate(_STATES)}
_START = _STATE_NO[(-1, 0)]


def _stuff_through(state: int, value: int, width: int) -> tuple[int, int]:
    """Stuff bits inserted into the ``width`` bits of ``value`` (MSB first) sent from stuffing
    state number ``state``, and the state number after them."""
    count, (last, run) = 0, _STATES[state]
    for i in range(width - 1, -1, -1):
        k, last, run = _step(last, run, (value >> i) & 1)
        count += k
    return count, _STATE_NO[(last, run)]


def _step_table(width: int) -> list[int]:
    """Per state number s and ``width``-bit value v, at ``s << width | v``: the stuff bits
    they insert << 4 | the state number after them."""
    table = []
    for state in range(len(_STATES)):
        for value in range(1 << width):
            count, after = _stuff_through(state, value, width)
            table.append(count << 4 | after)
    return table


#: a byte of the data field or the CRC's last 8 bits; the CRC's first 7 bits
_BYTE_STEP, _SEVEN_STEP = _step_table(8), _step_table(7)
#: :data:`_BYTE_STEP` laid out for :func:`frame_bits`' loop over the data bytes: at
#: ``state << 8 | byte`` the stuff bits << 15 | the state after them << 8, so that the next
#: index is the entry ``& 0xF00 | byte`` and the stuff bits of a frame's bytes are the sum of
#: its entries >> 15 (8 bytes' states, < 15 << 8 each, stay below 1 << 15)
_DATA_STEP = [(step >> 4) << 15 | (step & 15) << 8 for step in _BYTE_STEP]
#: per frame head (SOF, identifier, RTR, IDE, r0, DLC: 19 bits): its CRC-15, the stuff bits
#: in it and the stuffing state after it (few COB-IDs, few lengths)
_HEADS: dict[int, tuple[int, int, int]] = {}


def _head(head: int) -> tuple[int, int, int]:
    known = _HEADS.get(head)
    if known is None:
        count, state = _stuff_through(_START, head, 19)
        known = _HEADS[head] = (_crc15_of_int(head, 19), count, state)
    return known


def frame_bits(can_id: int, data: bytes | bytearray = b"", remote: bool = False,
               dlc: int | None = None) -> int:
    """Bits a CAN 2.0A base frame occupies on the wire, SOF to the end of IFS, stuffing included.

    One pass over the data bytes: the CRC-15 and the stuffing state advance a byte at a time
    (tables per byte), from the head's, which is computed once per COB-ID and length; equal
    to :func:`reference_frame_bits`, which walks the bits.

    :param can_id: the 11-bit identifier
    :param data: the data bytes
    :param remote: a remote frame (no data field)
    :param dlc: the DLC of a remote frame (default: ``len(data)``)
    :raises ValueError: ``can_id`` is no 11-bit identifier
    """
    if not 0 <= can_id <= 0x7FF:
        raise ValueError(f"identifier 0x{can_id:X} is not an 11-bit base identifier")
    payload = b"" if remote else data if type(data) in (bytes, bytearray) else bytes(data)
    n = len(payload) if dlc is None else dlc
    # SOF(0) ID(11) RTR IDE(0) r0(0) DLC(4): 19 bits
    head = (can_id << 7) | ((1 if remote else 0) << 6) | (n & 0xF)
    crc, count, state = _HEADS.get(head) or _head(head)
    table, steps = _CRC_TABLE, _DATA_STEP
    step = state << 8
    total = 0
    for byte in payload:  # crc < 1 << 15: crc >> 7 is a byte
        crc = ((crc << 8) & 0x7FFF) ^ table[(crc >> 7) ^ byte]
        step = steps[(step & 0xF00) | byte]
        total += step
    count += total >> 15
    step = _SEVEN_STEP[(step & 0xF00) >> 1 | crc >> 8]
    count += (step >> 4) + (_BYTE_STEP[(step & 15) << 8 | (crc & 0xFF)] >> 4)
    return 34 + 8 * len(payload) + count + TAIL_BITS


def reference_frame_bits(can_id: int, data: bytes = b"", remote: bool = False) -> int:
    """:func:`frame_bits` spelled out bit by bit (the test compares both).

    Parameters ``can_id``, ``data`` and ``remote`` as :func:`frame_bits`.
    """
    payload = b"" if remote else bytes(data)
    head = [0] + _bits(can_id, 11) + [1 if remote else 0, 0, 0] + _bits(len(payload), 4)
    for byte in payload:
        head += _bits(byte, 8)
    head += _bits(crc15(head), 15)
    return len(head) + stuff_count(head) + TAIL_BITS


def worst_frame_bits(n_bytes: int) -> int:
    """The classical upper bound of a base frame's bits: 34 + 8n stuffable bits, (34+8n-1)/4 stuff.

    :param n_bytes: data bytes (0-8)
    """
    stuffable = 34 + 8 * n_bytes
    return stuffable + (stuffable - 1) // 4 + TAIL_BITS


def frame_seconds(bits: int, bitrate: int) -> float:
    """Wire time (s) of ``bits`` at ``bitrate`` bit/s."""
    return bits / bitrate


def cycle_payloads(slots: int) -> list[int]:
    """Data bytes of each frame of one SYNC cycle: SYNC, the images, the position PDOs.

    :param slots: the station's modules (1-8)
    :raises ValueError: ``slots`` outside 1-8
    """
    if not 1 <= slots <= 8:
        raise ValueError(f"slots {slots} outside 1-8")
    positions = [4 * len([s for s in (2 * g + 1, 2 * g + 2) if s <= slots])
                 for g in range((slots + 1) // 2)]
    return [0] + [8] * slots + positions


def cycle_bits(slots: int) -> int:
    """Worst-case bits of one SYNC cycle of ``slots`` modules (SYNC + TPDOs)."""
    return sum(worst_frame_bits(n) for n in cycle_payloads(slots))


def cycle_seconds(slots: int, bitrate: int) -> float:
    """Worst-case wire time (s) of SYNC -> end of the last TPDO of one cycle.

    :param slots: the station's modules (1-8)
    :param bitrate: the bus's bit rate (bit/s)
    """
    return frame_seconds(cycle_bits(slots), bitrate)


def budget_bits(slots: int) -> int:
    """The bits a cycle must find room for: the cycle plus the register-traffic reserve.

    :param slots: the station's modules (1-8)
    """
    return cycle_bits(slots) + SDO_RESERVE_FRAMES * worst_frame_bits(8)


def max_cycle_rate(slots: int, bitrate: int) -> float:
    """Highest SYNC rate (Hz) at which the cycle and the reserve fit the wire, rounded down to 10 Hz.

    :param slots: the station's modules (1-8)
    :param bitrate: the bus's bit rate (bit/s)
    """
    return math.floor(bitrate / budget_bits(slots) / 10.0) * 10.0


def fits(slots: int, bitrate: int, rate_hz: float) -> bool:
    """True when ``rate_hz`` cycles per second of ``slots`` modules fit at ``bitrate``."""
    return rate_hz * budget_bits(slots) <= bitrate


def stations_cycle_bits(slot_counts: Sequence[int]) -> int:
    """Worst-case bits of one cycle of several stations on one bus: ONE SYNC, their TPDOs.

    :param slot_counts: each station's modules
    """
    sync = worst_frame_bits(0)
    return sync + sum(cycle_bits(n) - sync for n in slot_counts)


def stations_budget_bits(slot_counts: Sequence[int]) -> int:
    """:func:`budget_bits` of several stations: their cycle plus one register-traffic reserve.

    The node runs one register service at a time, so the reserve is the bus's, not per station.

    :param slot_counts: each station's modules
    """
    return stations_cycle_bits(slot_counts) + SDO_RESERVE_FRAMES * worst_frame_bits(8)


def stations_fits(slot_counts: Sequence[int], bitrate: int, rate_hz: float) -> bool:
    """True when ``rate_hz`` cycles of every station together fit at ``bitrate``.

    :param slot_counts: each station's modules
    """
    return rate_hz * stations_budget_bits(slot_counts) <= bitrate


def stations_max_cycle_rate(slot_counts: Sequence[int], bitrate: int) -> float:
    """Highest SYNC rate (Hz, rounded down to 10 Hz) for all stations together.

    :param slot_counts: each station's modules
    :param bitrate: the bus's bit rate (bit/s)
    """
    return math.floor(bitrate / stations_budget_bits(slot_counts) / 10.0) * 10.0


def rate_table() -> str:
    """The Markdown table of :func:`max_cycle_rate` per slot count and bit rate (docs/canopen.md)."""
    head = "| slots | " + " | ".join(f"{b // 1000} kbit/s" for b in TABLE_BITRATES) + " |"
    rule = "|---|" + "---|" * len(TABLE_BITRATES)
    rows = [f"| {n} | " + " | ".join(f"{max_cycle_rate(n, b):.0f} Hz" for b in TABLE_BITRATES)
            + " |" for n in range(1, 9)]
    return "\n".join([head, rule, *rows])


__all__ = ["SDO_RESERVE_FRAMES", "TABLE_BITRATES", "budget_bits", "crc15", "cycle_bits",
           "cycle_payloads", "cycle_seconds", "fits", "frame_bits", "frame_seconds",
           "max_cycle_rate", "rate_table", "stations_budget_bits", "stations_cycle_bits",
           "stations_fits", "stations_max_cycle_rate", "stuff_count", "worst_frame_bits"]
