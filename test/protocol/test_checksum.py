"""TR "Check sum" format (001 §5.2.4.2): frame layout from the manual's example, the rules of
§5.2.1/§5.2.4.2, and the checksum's error detection ("Hammingdistanz von 6 ... erkennt ... bis
zu 5 Fehler je Codewort"; German text of 001 §5.2.4.2, the English copy lost its heading).

The checksum polynomial is not in the manual: the simulation uses CAN's CRC-15 with a final
XOR (ssi_bridge/protocol/checksum.py); the tests check that this choice has the properties the
manual states, not TR's bits.
"""

from __future__ import annotations

import random
from itertools import combinations

import pytest

from ssi_bridge.protocol.checksum import (DATA_BITS, WIDTH, code_word, crc15, min_weight,
                                         syndrome)
from ssi_bridge.protocol.codes import Code
from ssi_bridge.protocol.encoder_config import FrameFormat, SpecialBit
from ssi_bridge.protocol.families import family_config
from ssi_bridge.sim.encoder.encoder import make_encoder
from ssi_bridge.protocol.layout import decode_area, encode_area
from ssi_bridge.sim.encoder.motion import Still
from ssi_bridge.exceptions import ConfigError
from ssi_bridge.protocol.frame_check import FrameCheck


def _manual_example(value: int) -> tuple[int, object]:
    # 001 §5.2.4.2 example: 4096 steps/revolution (12 bits), 1024 revolutions (10 bits),
    # "Total number of steps = 22 bits, this corresponds to 22 data bits", code binary: the
    # Number of data bits typed in is 22 (001 §5.2.1 "must be typed in exactly")
    enc = make_encoder("TR_CHECKSUM", Still(0.0), steps_per_rev=4096, revolutions_numerator=1024,
                       data_bits=22)
    enc.apply_preset(0.0, value)
    return enc.frame_at(0.0).bits, enc.config


@pytest.mark.parametrize("value", [0, 1, 4095, 4096, 0b1010101010_101010101010, 4096 * 1024 - 1])
def test_frame_layout_of_the_manual_example(value: int) -> None:
    # 001 §5.2.4.2 table: clocks 1-2 "0 0", 3-12 "P 2^21 - P 2^12" (12 bit number of
    # revolutions), 13-24 "P 2^11 - P 2^0", 25-28 "0 0 0 0" (16 bit steps per revolution),
    # 29-43 "CRC 2^14 - CRC 2^0" (15 bit TR check sum), MSB first
    bits, cfg = _manual_example(value)
    assert (cfg.data_bits, cfg.field_bits, cfg.frame_bits) == (22, 28, 43)
    s = format(bits, "043b")
    assert s[0:2] == "00"
    assert s[2:12] == format(value >> 12, "010b")
    assert s[12:24] == format(value & 0xFFF, "012b")
    assert s[24:28] == "0000"
    assert int(s[28:43], 2) == crc15(int(s[0:28], 2))
    assert syndrome(bits) == 0
    assert decode_area(cfg, bits >> WIDTH) == value == int(s[2:24], 2)


def test_full_resolution_fills_all_28_data_bits() -> None:
    # "28 Datenbits ... Anzahl Umdrehungen = 12 Bit, Schrittzahl pro Umdrehung = 16 Bit, dies
    # entspricht einer max. Gesamtmesslänge von 65536 Schritte/Umdrehung x 4096 Umdrehungen"
    cfg = family_config("TR_CHECKSUM", steps_per_rev=65536)
    top = 65536 * 4096 - 1
    assert encode_area(cfg, top) == (1 << DATA_BITS) - 1
    assert cfg.frame_bits == DATA_BITS + 15 == 43


@pytest.mark.parametrize("override, why", [
    # "As transmission code Binary must be selected"
    (dict(code=Code.GRAY), "binary"),
    (dict(special_bits=(SpecialBit.ENCODER_ERROR,)), "special"),   # "ohne SSI-Sonderbits"
    # 16 bits of steps per revolution at most
    (dict(steps_per_rev=131072, revolutions_numerator=16), "singleturn"),
    (dict(turn_bits=13), "turn_bits 12"),                   # fixed 12 + 16 field layout
    # "the Number of data bits required for the programmed Total number of steps must be
    # typed in exactly" (§5.2.1): 4096 x 4096 steps need 24, 4096 x 1024 need 22
    (dict(data_bits=28), "needs exactly 24"),
    (dict(data_bits=25), "needs exactly 24"),
    (dict(revolutions_numerator=1024, data_bits=24), "needs exactly 22"),
    (dict(revolutions_numerator=1024, data_bits=21), "values need 22 bits"),
    # §5.2.1 "Check sum: max. number of data bits <= 28"
    (dict(data_bits=29), "<= 28"),
])
def test_rules_of_the_check_sum_format(override: dict, why: str) -> None:
    with pytest.raises(ConfigError, match=why):
        family_config("TR_CHECKSUM", **override)


@pytest.mark.parametrize("override, data_bits", [
    ({}, 24),                                                   # 4096 x 4096
    (dict(revolutions_numerator=1024), 22),                     # the manual's example
    (dict(revolutions_numerator=1024, data_bits=22), 22),       # as typed in, §5.2.4.2
    (dict(steps_per_rev=65536), 28),                            # the largest, §5.2.4.2
    (dict(steps_per_rev=1024, revolutions_numerator=100), 17),  # 102400 steps
])
def test_number_of_data_bits_is_the_manuals(override: dict, data_bits: int) -> None:
    # 001 §5.2.1: Number of data bits = the bits of the total number of steps; the field on the
    # wire stays 12 + 16 bits and the frame 43 clocks whatever the number (§5.2.4.2)
    cfg = family_config("TR_CHECKSUM", **override)
    assert (cfg.data_bits, cfg.field_bits, cfg.position_bits, cfg.frame_bits) == \
        (data_bits, 28, 28, 43)


def test_the_simulated_checksum_has_hamming_distance_6() -> None:
    # "arbeitet mit einer Hammingdistanz von 6": exhaustive over all flip patterns of up to
    # 6 bits of the 43-bit code word (meet in the middle, checksum.min_weight)
    assert min_weight(DATA_BITS) == 6
    # CAN's claim for this generator: distance 6 up to 112-bit code words (97 data bits)
    assert min_weight(97) == 6


def test_it_is_the_can_crc15_generator() -> None:
    # CRC-15/CAN check value of "123456789" is 0x059E (init 0, no final XOR): the final XOR
    # of the simulation (0x7FFF) comes on top
    assert crc15(int.from_bytes(b"123456789", "big"), 72) ^ 0x7FFF == 0x059E


def test_broken_lines_give_no_valid_word() -> None:
    # "Zudem lassen sich unterbrochene Takt- oder Datenleitungen im Empfangsgerät erkennen":
    # data wire broken -> every bit LOW (003 SB.0); clock broken -> the line stays idle high
    assert syndrome(0) != 0
    assert syndrome((1 << 43) - 1) != 0
    cfg = family_config("TR_CHECKSUM")
    for n in (43, 32):   # also when the XN-1SSI reads only 32 of the 43 bits
        check = FrameCheck(cfg, n)
        assert check.check(0).corrupt and check.check((1 << n) - 1).corrupt


@pytest.mark.parametrize("flips", [1, 2, 3, 4, 5])
def test_up_to_five_flipped_bits_are_detected(flips: int) -> None:
    # "erkennt auf diese Weise bis zu 5 Fehler je Codewort": every single and double flip
    # exhaustively, 3..5 flips on 1000 random patterns, at several positions
    rng = random.Random(flips)
    cfg = family_config("TR_CHECKSUM")
    check = FrameCheck(cfg, 43)
    for value in (0, 1, 0x00ABCDE, 4096 * 4096 - 1):
        word = code_word(encode_area(cfg, value))
        assert not check.check(word).corrupt
        if flips <= 2:
            patterns = combinations(range(43), flips)
        else:
            patterns = (rng.sample(range(43), flips) for _ in range(1000))
        for idx in patterns:
            e = 0
            for j in idx:
                e |= 1 << j
            assert check.check(word ^ e).corrupt


def test_checksum_preset_is_the_check_sum_format() -> None:
    cfg = family_config("TR_CHECKSUM")
    assert cfg.frame_format is FrameFormat.CHECKSUM and cfg.code is Code.BINARY
    assert cfg.special_bits == ()
