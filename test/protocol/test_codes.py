"""Codes of 004 §2.4 (Table 1, Gray-excess) and the BCD column of the same table."""

from __future__ import annotations

import pytest
from hypothesis import given, strategies as st

from ssi_bridge.protocol.codes import (Code, bcd_decode, bcd_encode, bin_to_gray, decode, encode,
                                      gray_excess_decode, gray_excess_encode, gray_excess_offset,
                                      gray_to_bin)

# 004 §2.4 Table 1: decimal, binary, BCD, Gray (as printed)
TABLE_1 = [
    (0, "0000", "0000000", "0000"), (1, "0001", "0000001", "0001"),
    (2, "0010", "0000010", "0011"), (3, "0011", "00000011", "0010"),
    (4, "0100", "00000100", "0110"), (5, "0101", "00000101", "0111"),
    (6, "0110", "00000110", "0101"), (7, "0111", "00000111", "0100"),
    (8, "1000", "00001000", "1100"), (9, "1001", "00001001", "1101"),
    (10, "1010", "00010000", "1111"), (11, "1011", "00010001", "1110"),
    (12, "1100", "00010010", "1010"), (13, "1101", "00010011", "1011"),
    (14, "1110", "00010100", "1001"), (15, "1111", "00010101", "1000"),
]


@pytest.mark.parametrize("dec, binary, bcd, gray", TABLE_1)
def test_table_1_gray_and_bcd(dec: int, binary: str, bcd: str, gray: str) -> None:
    """004 §2.4 Table 1, rows 0-15: Gray and BCD codes of each decimal value."""
    assert int(binary, 2) == dec
    assert bin_to_gray(dec) == int(gray, 2), f"Gray of {dec}"
    assert gray_to_bin(int(gray, 2)) == dec
    assert bcd_encode(dec) == int(bcd, 2), f"BCD of {dec}"
    assert bcd_decode(int(bcd, 2)) == dec


def test_gray_changes_one_bit_per_step() -> None:
    """004 §2.4: only one bit changes from one position value to the next."""
    for v in range(4095):
        assert bin(bin_to_gray(v) ^ bin_to_gray(v + 1)).count("1") == 1


@given(st.integers(min_value=0, max_value=(1 << 64) - 1))
def test_gray_round_trip_64_bits(v: int) -> None:
    """004 §2.4: Gray decode is the inverse of encode for any width up to 64 bits."""
    assert gray_to_bin(bin_to_gray(v)) == v


@pytest.mark.parametrize("resolution, offset", [(360, 76), (1000, 12), (3600, 248), (8192, 0), (12, 2)])
def test_gray_excess_offset(resolution: int, offset: int) -> None:
    """004 §2.4: the capped section is centred in the full code, e = (2**N - R) / 2."""
    assert gray_excess_offset(resolution) == offset


@pytest.mark.parametrize("resolution", [360, 1000, 3600, 12, 100])
def test_gray_excess_single_bit_at_zero_crossing(resolution: int) -> None:
    """004 §2.4: Gray-excess changes a single bit even when passing through zero."""
    for v in range(resolution):
        nxt = (v + 1) % resolution
        diff = gray_excess_encode(v, resolution) ^ gray_excess_encode(nxt, resolution)
        assert bin(diff).count("1") == 1, f"{v}->{nxt} changes {diff:b}"
        assert gray_excess_decode(gray_excess_encode(v, resolution), resolution) == v


def test_gray_excess_rejects_codes_outside_the_section() -> None:
    """004 §2.4: codes outside the capped section are not valid positions."""
    with pytest.raises(ValueError):
        gray_excess_decode(bin_to_gray(0), 360)


def test_bcd_rejects_nibbles_above_nine() -> None:
    """004 Table 1 BCD column: one decimal digit per nibble, 0xA..0xF are invalid."""
    with pytest.raises(ValueError):
        bcd_decode(0x1A)


@pytest.mark.parametrize("code", list(Code))
def test_encode_decode_dispatch(code: Code) -> None:
    """001 §5.2.2 transmit codes round-trip through the dispatcher."""
    for v in (0, 1, 9, 10, 359):
        assert decode(encode(v, code, 360), code, 360) == v
