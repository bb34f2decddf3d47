"""Output codes of SSI encoders: binary, Gray, Gray-excess and BCD (004 §2.4, 001 §5.2.2).

Shared by the encoder (encode) and every master (decode): the XN-1SSI module stage imports
:func:`gray_to_bin` from here.

Gray-excess (004 §2.4, "capped Gray code"): for a resolution ``R`` that is not a power of
two the encoder sends the section of the ``N``-bit Gray code (``N = bit_length(R - 1)``) that
is centred in the full code, i.e. ``gray(value + e)`` with the excess offset
``e = (2**N - R) // 2``. For even ``R`` the step from ``R - 1`` back to ``0`` then changes only
the MSB (reflection property of the Gray code), which is the point of the code. For odd ``R``
no single-bit wrap exists; we still use ``e = (2**N - R) // 2`` (documented in
docs/encoder_line.md).
"""

from __future__ import annotations

from enum import Enum

from ssi_bridge.exceptions import ConfigError


class Code(Enum):
    """Transmit code of the position bits (004 §2.4 Table 1, 001 §5.2.2)."""

    BINARY = "binary"
    GRAY = "gray"
    GRAY_EXCESS = "gray_excess"
    BCD = "bcd"


def bin_to_gray(value: int) -> int:
    """Gray code of a non-negative integer (004 §2.4 Table 1).

    :param value: the binary value (>= 0)
    """
    return value ^ (value >> 1)


def gray_to_bin(gray: int) -> int:
    """Binary value of a Gray-coded non-negative integer of any width.

    Bit ``i`` of the result is the XOR of Gray bits ``i`` and above; doubling shifts make
    this ``log2(width)`` steps instead of one per bit.

    :param gray: the Gray-coded value (>= 0)
    """
    value = gray
    shift = 1
    width = gray.bit_length()
    while shift < width:
        value ^= value >> shift
        shift <<= 1
    return value


def gray_excess_offset(resolution: int) -> int:
    """Excess ``e`` of the Gray-excess code for ``resolution`` steps (004 §2.4).

    ``e = (2**N - R) // 2`` with ``N = bit_length(R - 1)``; 0 for powers of two.

    :raises ConfigError: ``resolution`` below 2
    """
    if resolution < 2:
        raise ConfigError(f"Gray-excess resolution {resolution} must be >= 2")
    n = (resolution - 1).bit_length()
    return ((1 << n) - resolution) // 2


def gray_excess_encode(value: int, resolution: int) -> int:
    """Gray-excess code of ``value`` in ``0 .. resolution - 1`` (004 §2.4).

    :raises ValueError: ``value`` outside 0..``resolution`` - 1
    """
    if not 0 <= value < resolution:
        raise ValueError(f"value {value} outside 0..{resolution - 1}")
    return bin_to_gray(value + gray_excess_offset(resolution))


def gray_excess_decode(code: int, resolution: int) -> int:
    """Inverse of :func:`gray_excess_encode`; raises ``ValueError`` outside the capped range.

    :param code: the Gray-excess code word
    :param resolution: the encoder's steps
    """
    value = gray_to_bin(code) - gray_excess_offset(resolution)
    if not 0 <= value < resolution:
        raise ValueError(f"Gray-excess code 0x{code:X} outside the capped range of {resolution}")
    return value


def bcd_encode(value: int) -> int:
    """Packed BCD of a non-negative integer, one decimal digit per nibble (004 Table 1).

    :param value: the value (>= 0)
    :raises ValueError: ``value`` is negative
    """
    if value < 0:
        raise ValueError(f"BCD of negative value {value}: use a negative-value format (001 §5.2.5)")
    out = 0
    shift = 0
    while True:
        value, digit = divmod(value, 10)
        out |= digit << shift
        shift += 4
        if value == 0:
            return out


def bcd_decode(code: int) -> int:
    """Integer of a packed BCD word; raises ``ValueError`` on a nibble above 9.

    :param code: the packed BCD word
    """
    value = 0
    scale = 1
    while code:
        digit = code & 0xF
        if digit > 9:
            raise ValueError(f"invalid BCD nibble 0x{digit:X} in 0x{code:X}")
        value += digit * scale
        scale *= 10
        code >>= 4
    return value


def encode(value: int, code: Code, resolution: int = 0) -> int:
    """Encode a non-negative value with ``code`` (``resolution`` only for Gray-excess)."""
    if code is Code.BINARY:
        return value
    if code is Code.GRAY:
        return bin_to_gray(value)
    if code is Code.BCD:
        return bcd_encode(value)
    return gray_excess_encode(value, resolution)


def decode(word: int, code: Code, resolution: int = 0) -> int:
    """Inverse of :func:`encode`.

    :param word: the code word
    :param code: the code it is in
    :param resolution: the encoder's steps (Gray-excess only)
    """
    if code is Code.BINARY:
        return word
    if code is Code.GRAY:
        return gray_to_bin(word)
    if code is Code.BCD:
        return bcd_decode(word)
    return gray_excess_decode(word, resolution)
