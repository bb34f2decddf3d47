"""Frame assembly and its inverse: output value <-> position area <-> frame bits.

Encoding order (and the reasons):

1. negative values (origin < 0) become complement or sign + value in ``data_bits``
   (001 §5.2.5 table: 16-bit binary -1 = 0xFFFF / 0x8001, BCD -1 = 0x9999 / 0x8001);
2. every code is applied to the value *before* placement, so the non-assigned bits stay 0
   in every code (004 §3.1 "For resolutions below 14 bits, non-assigned bits are filled
   with 0", "At lower resolution, the transmission frame is filled with zero bits"; §3.4
   Tannenbaum "the MSB or LSB side is filled with '0'"). Gray-coding the placed word would
   copy the value's LSB into the first filler bit. Tannenbaum Gray is the Gray code of the
   whole value (one bit changes per step, also across a revolution, 004 §2.4) split at the
   singleturn width. A master that shifts the filler bits out and Gray-decodes gets the
   value back (000 REG_PARA1 INVALID_BITS_LSB);
3. placement: right-justified, MSB-justified or Tannenbaum (config.py), then trailing zero
   bits, then SSI-SHIFT-RIGHT (004 §3.4);
4. special bits are appended after the LSB (001 §5.5, 004 §2.3), parity last (001 §5.5.7).
"""

from __future__ import annotations

from ssi_bridge.protocol.codes import (Code, bcd_decode, bcd_encode, bin_to_gray, decode, encode,
                                      gray_to_bin)
from ssi_bridge.protocol.encoder_config import Alignment, EncoderConfig, Negative, SpecialBit


def _code_magnitude(cfg: EncoderConfig, mag: int) -> int:
    if cfg.code is Code.BCD:
        return bcd_encode(mag)
    if cfg.code is Code.GRAY:
        return bin_to_gray(mag)
    return mag


def _decode_magnitude(cfg: EncoderConfig, word: int) -> int:
    if cfg.code is Code.BCD:
        return bcd_decode(word)
    if cfg.code is Code.GRAY:
        return gray_to_bin(word)
    return word


def _encode_negative_capable(cfg: EncoderConfig, value: int) -> int:
    """Right-justified word of a value that may be negative (001 §5.2.5)."""
    db = cfg.field_bits
    if value >= 0:
        return _code_magnitude(cfg, value)
    if cfg.negative is Negative.SIGN_VALUE:
        return (1 << (db - 1)) | _code_magnitude(cfg, -value)
    if cfg.code is Code.BCD:
        return bcd_encode(10 ** (db // 4) + value)
    word = (1 << db) + value
    return bin_to_gray(word) if cfg.code is Code.GRAY else word


def _decode_negative_capable(cfg: EncoderConfig, word: int) -> int:
    db = cfg.field_bits
    if cfg.negative is Negative.SIGN_VALUE:
        sign = (word >> (db - 1)) & 1
        mag = _decode_magnitude(cfg, word & ~(1 << (db - 1)))
        return -mag if sign else mag
    if cfg.code is Code.BCD:
        full = 10 ** (db // 4)
        d = bcd_decode(word)
        return d - full if d >= full // 2 else d
    w = gray_to_bin(word) if cfg.code is Code.GRAY else word
    return w - (1 << db) if (w >> (db - 1)) & 1 else w


def _excess_origin(cfg: EncoderConfig) -> int:
    """What the code word counts from: Gray-excess codes the step in the range (value -
    origin, 004 §2.4); the other codes carry the value itself."""
    return cfg.origin if cfg.code is Code.GRAY_EXCESS else 0


def _tannenbaum_bits(cfg: EncoderConfig) -> tuple[int, int]:
    """(singleturn field width, singleturn resolution bits n) of a Tannenbaum layout."""
    return cfg.field_bits - cfg.turn_bits, int(cfg.steps_per_rev).bit_length() - 1


def encode_area(cfg: EncoderConfig, value: int) -> int:
    """Position area (``cfg.position_bits`` wide) carrying output ``value``.

    The code word is formed from the value first and then placed, so filler bits are 0 in
    every code (004 §3.1, §3.4).
    """
    if cfg.origin < 0:
        word = _encode_negative_capable(cfg, value)
    else:
        coded = encode(value - _excess_origin(cfg), cfg.code, cfg.range_steps)
        if cfg.alignment is Alignment.TANNENBAUM:
            field, n = _tannenbaum_bits(cfg)
            word = ((coded >> n) << field) | ((coded & ((1 << n) - 1)) << (field - n))
        elif cfg.alignment is Alignment.LEFT:
            word = coded << (cfg.field_bits - cfg.value_bits)
        else:
            word = coded
    area = word << cfg.trailing_zero_bits
    return area >> 1 if cfg.shift_right else area


def decode_area(cfg: EncoderConfig, area: int) -> int:
    """Output value from a position area (inverse of :func:`encode_area`).

    With ``shift_right`` the LSB is lost on the wire (004 §3.4), so the value comes back
    with its LSB cleared (binary; in the other codes the last code bit is lost).

    :param cfg: the encoder's layout
    :param area: the position area's bits
    """
    if cfg.shift_right:
        area <<= 1
    word = area >> cfg.trailing_zero_bits
    if cfg.origin < 0:
        return _decode_negative_capable(cfg, word)
    if cfg.alignment is Alignment.TANNENBAUM:
        field, n = _tannenbaum_bits(cfg)
        coded = ((word >> field) << n) | ((word & ((1 << field) - 1)) >> (field - n))
    elif cfg.alignment is Alignment.LEFT:
        coded = word >> (cfg.field_bits - cfg.value_bits)
    else:
        coded = word
    return decode(coded, cfg.code, cfg.range_steps) + _excess_origin(cfg)


def assemble(cfg: EncoderConfig, area: int, levels: list[int]) -> int:
    """Frame bits: the position area followed by the special-bit levels and zero fill.

    :param cfg: the encoder's layout
    :param area: the position area's bits
    :param levels: the wire level of each special bit, in the layout's order
    """
    frame = area
    for level in levels:
        frame = (frame << 1) | level
    return frame << (cfg.frame_bits - cfg.position_bits - len(levels))


def split(cfg: EncoderConfig, frame: int) -> tuple[int, dict[SpecialBit, int]]:
    """Position area and the wire level of each special bit (ZERO fillers dropped).

    :param cfg: the encoder's layout
    :param frame: the frame's bits, first transmitted = MSB
    """
    n_spec = len(cfg.special_bits)
    fill = cfg.frame_bits - cfg.position_bits - n_spec
    body = frame >> fill
    levels: dict[SpecialBit, int] = {}
    for i, bit in enumerate(cfg.special_bits):
        if bit is not SpecialBit.ZERO:
            levels[bit] = (body >> (n_spec - 1 - i)) & 1
    return body >> n_spec, levels
