"""Frame layouts of 001 (negative values §5.2.5, 26-bit + repeat §5.2.4.3, no special format)."""

from __future__ import annotations

import pytest

from ssi_bridge.protocol.codes import Code
from ssi_bridge.protocol.encoder_config import (Alignment, EncoderConfig, FrameFormat, Negative,
                                       SpecialBit)
from ssi_bridge.protocol.layout import decode_area, encode_area, split
from ssi_bridge.exceptions import ConfigError

# 001 §5.2.5 table (16 bits): value, binary+complement, binary+sign, BCD+complement, BCD+sign
NEGATIVE_TABLE = [
    (2, 0x0002, 0x0002, 0x0002, 0x0002),
    (1, 0x0001, 0x0001, 0x0001, 0x0001),
    (0, 0x0000, 0x0000, 0x0000, 0x0000),
    (-1, 0xFFFF, 0x8001, 0x9999, 0x8001),
    (-2, 0xFFFE, 0x8002, 0x9998, 0x8002),
    (-3, 0xFFFD, 0x8003, 0x9997, 0x8003),
]


def _neg_cfg(code: Code, neg: Negative) -> EncoderConfig:
    return EncoderConfig(name="TR16", steps_per_rev=1000, revolutions_numerator=10,
                         data_bits=16, origin=-5000, code=code, negative=neg)


@pytest.mark.parametrize("value, bin_c, bin_s, bcd_c, bcd_s", NEGATIVE_TABLE)
def test_negative_values_table(value: int, bin_c: int, bin_s: int, bcd_c: int, bcd_s: int) -> None:
    """001 §5.2.5 table: complement and sign + value, binary and BCD, 16 bits."""
    cases = [(Code.BINARY, Negative.COMPLEMENT, bin_c), (Code.BINARY, Negative.SIGN_VALUE, bin_s),
             (Code.BCD, Negative.COMPLEMENT, bcd_c), (Code.BCD, Negative.SIGN_VALUE, bcd_s)]
    for code, neg, word in cases:
        cfg = _neg_cfg(code, neg)
        assert encode_area(cfg, value) == word, f"{code.value}+{neg.value} of {value}"
        assert decode_area(cfg, word) == value


def _repeat_cfg(data_bits: int, specials: tuple[SpecialBit, ...]) -> EncoderConfig:
    # 001 §5.2.4.3 example: 1024 steps/rev x 4096 revolutions = 22 bits
    return EncoderConfig(name="TR", steps_per_rev=1024, revolutions_numerator=4096,
                         data_bits=data_bits, frame_format=FrameFormat.REPEAT_26,
                         special_bits=specials)


def test_26bit_repeat_right_justified_example() -> None:
    """001 §5.2.4.3: data bits 24 -> clocks 1-2 zero, 3-24 P2^21..P2^0, 25-26 S1 S2."""
    cfg = _repeat_cfg(24, (SpecialBit.CAM1, SpecialBit.CAM2))
    assert cfg.frame_bits == 26
    area = encode_area(cfg, (1 << 22) - 1)
    assert area == (1 << 22) - 1 and cfg.position_bits == 24


def test_26bit_repeat_left_justified_example() -> None:
    """001 §5.2.4.3: data bits 22 -> clocks 1-22 position, 23-26 S1..S4."""
    specials = (SpecialBit.CAM1, SpecialBit.CAM2, SpecialBit.CAM3, SpecialBit.CAM4)
    cfg = _repeat_cfg(22, specials)
    from ssi_bridge.protocol.layout import assemble
    frame = assemble(cfg, encode_area(cfg, 0x2AAAAA), [1, 0, 1, 1])
    assert frame == (0x2AAAAA << 4) | 0b1011
    area, levels = split(cfg, frame)
    assert decode_area(cfg, area) == 0x2AAAAA
    assert [levels[b] for b in specials] == [1, 0, 1, 1]


def test_26bit_repeat_pads_with_trailing_zeros() -> None:
    """001 §5.2.4.3: always 26 bits; unused special-bit clocks send trailing zeros."""
    cfg = _repeat_cfg(22, (SpecialBit.CAM1,))
    from ssi_bridge.protocol.layout import assemble
    assert assemble(cfg, 5, [1]) == ((5 << 1 | 1) << 3)


@pytest.mark.parametrize("data_bits, specials", [
    (26, (SpecialBit.CAM1,)),
    (22, tuple(SpecialBit(b) for b in ("cam1", "cam2", "cam3", "cam4", "up"))),
])
def test_26bit_repeat_limit(data_bits: int, specials: tuple[SpecialBit, ...]) -> None:
    """001 §5.2.1/§5.2.4.3: data bits + special bits must be <= 26."""
    with pytest.raises(ConfigError):
        _repeat_cfg(data_bits, specials)


def test_no_special_format_example_22_bits() -> None:
    """001 §5.2.4.1 example: 4096 steps x 1024 revolutions = 22 data bits, binary, MSB first."""
    cfg = EncoderConfig(steps_per_rev=4096, revolutions_numerator=1024, data_bits=22)
    assert cfg.range_steps == 1 << 22 and cfg.frame_bits == 22
    assert encode_area(cfg, 0x3FFFFF) == 0x3FFFFF


def test_total_steps_rounding_rule() -> None:
    """001 §5.1.2.2 example: 1348.073499 steps/rev x 4096/1 -> 5521709 steps (rounded)."""
    cfg = EncoderConfig(steps_per_rev=1348.073499, revolutions_numerator=4096, data_bits=23)
    assert cfg.range_steps == 5521709


@pytest.mark.parametrize("field, value", [
    ("revolutions_numerator", 0), ("revolutions_numerator", 256001),
    ("revolutions_divisor", 16385), ("data_bits", 0), ("data_bits", 65), ("overspeed_rpm", 5),
])
def test_config_ranges(field: str, value: int) -> None:
    """001 §5.1.2.2 / §5.2.1 / §5.4.2 parameter limits raise ConfigError."""
    with pytest.raises(ConfigError):
        EncoderConfig(**{field: value})


def test_parity_must_be_last() -> None:
    """001 §5.5.7: the parity special bit must be defined at the last digit."""
    with pytest.raises(ConfigError):
        EncoderConfig(special_bits=(SpecialBit.EVEN_PARITY, SpecialBit.TOGGLE))


def test_left_justified_lower_resolution_fills_lsb_with_zeros() -> None:
    """004 §3.1: AHS36 below 14 bits -> MSB-justified, non-assigned bits 0."""
    cfg = EncoderConfig(steps_per_rev=1024, revolutions_numerator=1, data_bits=14,
                        alignment=Alignment.LEFT)
    assert encode_area(cfg, 1023) == 1023 << 4
