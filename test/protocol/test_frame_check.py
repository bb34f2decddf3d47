"""Master-side frame checks: parity (001 §5.5.7), zero bits (004 §3.1, §3.4, §3.6), PowerFail (003)."""

from __future__ import annotations

import pytest

from ssi_bridge.protocol.codes import Code
from ssi_bridge.protocol.encoder_config import SpecialBit
from ssi_bridge.sim.encoder.encoder import make_encoder
from ssi_bridge.sim.encoder.motion import Still
from ssi_bridge.protocol.frame_check import FrameCheck


def _frame(family: str, step: float, **kw) -> tuple[int, object]:
    enc = make_encoder(family, Still(step), **kw)
    return enc.frame_at(0.0).bits, enc.config


def test_tr_parity_preset_layout() -> None:
    # 001 §5.2.1 "Special bits ... will be output after the data bits"; §5.5.7 "the Parity
    # ... special bit must always be defined at the last digit": 24 + error + parity
    enc = make_encoder("TR_PARITY")
    assert enc.frame_bits == 26
    assert enc.config.special_bits[-1] is SpecialBit.EVEN_PARITY


@pytest.mark.parametrize("value", [0, 1, 2, 3, 4095, 4096, 123457, 4096 * 4096 - 1])
def test_even_parity_makes_the_count_of_ones_even(value: int) -> None:
    # 001 §5.5.7: "If the SSI data word contains an odd number of "1", the special bit Even
    # Parity = "1" and supplements the checksum to even parity"
    bits, cfg = _frame("TR_PARITY", (value + 0.5) / 4096)
    assert bin(bits).count("1") % 2 == 0
    check = FrameCheck(cfg, 26)
    assert check.has_parity and not check.check(bits).parity_error
    for i in range(26):          # any single flipped bit breaks the parity
        assert check.check(bits ^ (1 << i)).corrupt


def test_odd_parity_by_inversion() -> None:
    # 001 §5.5.7 "By selection of the inverted Parity the Odd Parity ... can be deduced"
    bits, cfg = _frame("TR_PARITY", 7.5 / 4096, inverted_bits=frozenset({SpecialBit.EVEN_PARITY}))
    assert bin(bits).count("1") % 2 == 1
    assert not FrameCheck(cfg, 26).check(bits).parity_error


def test_power_fail_bit_is_the_last_bit() -> None:
    # 003 "The last data bit can be a PowerFail bit, i.e. the slave signals a power failure"
    enc = make_encoder("SSI25_POWERFAIL", Still(1.5 / 4096))
    check = FrameCheck(enc.config, 25)
    frame = enc.frame_at(0.0)
    assert frame.length == 25 and frame.bits == 1 << 1
    assert not check.check(frame.bits).power_failure
    enc.power_failure = True
    frame = enc.frame_at(0.001)
    assert frame.bits & 1 and check.check(frame.bits).power_failure
    assert frame.bits >> 1 == 1, "the 24 position bits are unchanged"


def test_filler_bits_are_checked() -> None:
    # 004 §3.1 "For resolutions below 14 bits, non-assigned bits are filled with 0": a 12-bit
    # AHS36 value leaves clocks 13 and 14 at 0
    bits, cfg = _frame("AHS36", 5.5 / 4096, steps_per_rev=4096, code=Code.GRAY)
    check = FrameCheck(cfg, 15)
    assert not check.check(bits).corrupt
    assert check.check(bits ^ 0b010).filler_error and check.check(bits ^ 0b100).filler_error
    assert not check.check(bits ^ 0b1000).filler_error   # a position bit: not a filler


def test_clocks_beyond_the_frame_read_zero() -> None:
    # 004 §3.6: "If more than 26 pulses are sent, the additional bits are output with "0""
    bits, cfg = _frame("TTK70", 0.0)
    check = FrameCheck(cfg, 28)
    assert not check.check(bits << 2).corrupt
    assert check.check((bits << 2) | 1).filler_error


def test_error_bits_are_reported() -> None:
    enc = make_encoder("TR_PARITY", Still(0.1))
    enc.set_error(True)
    verdict = FrameCheck(enc.config, 26).check(enc.frame_at(0.0).bits)
    assert verdict.encoder_error and not verdict.parity_error
