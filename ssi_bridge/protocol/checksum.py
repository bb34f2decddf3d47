"""The 15-bit checksum of TR's "Check sum" SSI format (001 §5.2.4.2), as simulated here.

001 §5.2.4.2 (German text "Prüfsumme"): 28 data bits without special bits, binary, MSB
first (12 bits number of revolutions, 16 bits steps per revolution), then "15 Prüfsummenbits
(MSB-Bit zuerst)"; the format "arbeitet mit einer Hammingdistanz von 6 und erkennt auf diese
Weise bis zu 5 Fehler je Codewort. Zudem lassen sich unterbrochene Takt- oder Datenleitungen
im Empfangsgerät erkennen."

The manual does not give TR's checksum (the format is "TR-eigen"), so this is a simulation
choice: CAN's CRC-15 generator x^15+x^14+x^10+x^8+x^7+x^4+x^3+1 (0x4599), initial value 0,
MSB first, over the 28 data bits as sent, and a final XOR with 0x7FFF. The generator gives
Hamming distance 6 at the 43-bit code word (:func:`min_weight` computes it, a test checks
it); the final XOR makes the all-0 word (data wire broken, read LOW, 003 SB.0) and the all-1
word (clock broken, the line stays idle high) invalid, as the manual says broken lines are
detected. A master of a real TR encoder needs TR's own checksum instead.
"""

from __future__ import annotations

from itertools import combinations

#: CAN CRC-15 generator without its x^15 term (simulation choice, see the module docstring)
POLY = 0x4599
#: final XOR: all-0 and all-1 words are not code words (simulation choice)
XOR_OUT = 0x7FFF
WIDTH = 15
#: the data part of the code word: 12 + 16 bits (001 §5.2.4.2)
DATA_BITS = 28
_MASK = (1 << WIDTH) - 1


def _table() -> tuple[int, ...]:
    """Register update for each byte value (one table step per 8 data bits)."""
    out = []
    for byte in range(256):
        crc = byte << (WIDTH - 8)
        for _ in range(8):
            crc = ((crc << 1) ^ POLY) & _MASK if crc >> (WIDTH - 1) else (crc << 1) & _MASK
        out.append(crc)
    return tuple(out)


_TABLE = _table()


def _remainder(data: int, n_bits: int) -> int:
    """data · x^15 mod the generator: the linear part of the checksum."""
    crc = 0
    lead = n_bits % 8
    for k in range(n_bits - 1, n_bits - 1 - lead, -1):   # bits that do not fill a byte
        fb = (crc >> (WIDTH - 1)) ^ ((data >> k) & 1)
        crc = ((crc << 1) & _MASK) ^ (POLY if fb else 0)
    for k in range(n_bits - lead - 8, -1, -8):
        crc = ((crc << 8) & _MASK) ^ _TABLE[((crc >> (WIDTH - 8)) ^ (data >> k)) & 0xFF]
    return crc


def crc15(data: int, n_bits: int = DATA_BITS) -> int:
    """The 15 checksum bits sent after the ``n_bits``-bit word ``data`` (MSB first)."""
    return _remainder(data, n_bits) ^ XOR_OUT


def code_word(data: int, n_bits: int = DATA_BITS) -> int:
    """Data followed by its checksum: the ``n_bits + 15`` bits on the wire.

    :param data: the data bits, first transmitted = MSB
    :param n_bits: how many data bits
    """
    return (data << WIDTH) | crc15(data, n_bits)


def syndrome(word: int, n_bits: int = DATA_BITS) -> int:
    """0 for a valid code word of ``n_bits`` data bits, else the checksum mismatch."""
    return crc15(word >> WIDTH, n_bits) ^ (word & _MASK)


def min_weight(n_bits: int = DATA_BITS) -> int | None:
    """Fewest bit flips of a code word (``n_bits`` data + checksum) that go unseen; None if > 6.

    A flip pattern e turns a code word into another one exactly when its linear syndrome
    (:func:`syndrome` of e, minus that of the zero word) is 0, so the smallest such weight is
    the Hamming distance. Exhaustive up to weight 6 by meeting in the middle: every pattern
    of weight <= 6 is the symmetric difference of two flip sets of at most 3 bits with equal
    syndromes, so all sets of 0..3 bits are bucketed by syndrome.
    """
    n = n_bits + WIDTH
    zero = syndrome(0, n_bits)
    cols = [syndrome(1 << j, n_bits) ^ zero for j in range(n)]
    buckets: dict[int, list[frozenset[int]]] = {}
    for w in range(4):
        for idx in combinations(range(n), w):
            s = 0
            for j in idx:
                s ^= cols[j]
            buckets.setdefault(s, []).append(frozenset(idx))
    best: int | None = None
    for sets in buckets.values():
        for a, b in combinations(sets, 2):
            d = len(a ^ b)
            if best is None or d < best:
                best = d
    return best
