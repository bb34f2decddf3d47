"""Frame layout of every family preset with a known position (004 §3, 001 §5)."""

from __future__ import annotations

import pytest

from ssi_bridge.protocol.encoder_config import Alignment, SpecialBit, SsiMode
from ssi_bridge.protocol.families import FAMILIES, family_config
from ssi_bridge.sim.encoder.encoder import make_encoder
from ssi_bridge.protocol.layout import decode_area, split
from ssi_bridge.sim.encoder.motion import Still
from ssi_bridge.exceptions import ConfigError


def _at(turns: int, step: int, spr: int) -> Still:
    """A shaft resting in the middle of step ``step`` of revolution ``turns``."""
    return Still(turns + (step + 0.5) / spr)


@pytest.mark.parametrize("family, overrides, turns, step, spr, bits, length", [
    # XN-1SSI default: 25-bit binary frame (12 + 13), no special bits
    ("GENERIC", {}, 5, 100, 8192, (5 << 13) | 100, 25),
    # 004 §3.1: clock 1-14 position (MSB-justified), clock 15 error bit
    ("AHS36", {}, 0, 1000, 16384, 1000 << 1, 15),
    # 004 §3.1: clock 1-12 multiturn, 13-26 singleturn, 27 error
    ("AHM36_MULTI", {}, 3, 5000, 16384, ((3 << 14) | 5000) << 1, 27),
    # 004 §3.2: 18 position bits + ERRDIG, ERRSI, ERRSYNC
    ("AFS60", {}, 0, 200000, 262144, 200000 << 3, 21),
    # 004 §3.2 example: 13-bit resolution -> 16 bits (13 data + 3 error)
    ("AFS60", {"steps_per_rev": 8192}, 0, 4000, 8192, 4000 << 3, 16),
    # 004 §3.2: multiturn 30 bits (12 + 18) + 3 error bits
    ("AFM60_MULTI", {}, 7, 9, 262144, ((7 << 18) | 9) << 3, 33),
    # 004 §3.2 example: 27-bit resolution -> 30 bits output
    ("AFM60_MULTI", {"steps_per_rev": 32768}, 7, 9, 32768, ((7 << 15) | 9) << 3, 30),
    # 004 §3.3: 25-bit resolution -> 28 bits (12 + 13 + 3 error)
    ("AFM60S_PRO", {"steps_per_rev": 8192}, 1, 2, 8192, ((1 << 13) | 2) << 3, 28),
    # 004 §3.4 Figure 18: 12 multiturn + 13 singleturn, 25 bits Tannenbaum
    ("ATM60", {}, 4095, 8191, 8192, (1 << 25) - 1, 25),
    # 004 §3.4 Figure 17: 13 multiturn + 12 singleturn
    ("ATM60_13_12", {}, 8000, 17, 4096, (8000 << 12) | 17, 25),
    # 004 §3.4: optional error bit at clock 26
    ("ATM60", {"special_bits": (SpecialBit.ERROR,)}, 2, 3, 8192, ((2 << 13) | 3) << 1, 26),
    # 004 §3.5: <= 8192 steps -> 13 bits, no error bits
    ("ARS60", {}, 0, 4242, 8192, 4242, 13),
    # 004 §3.5: > 8192 steps -> 15 bits + 2 error bits
    ("ARS60", {"steps_per_rev": 32768}, 0, 30000, 32768, 30000 << 2, 17),
    # 001 §5.2.4.1: 4096 x 4096, 24 data bits, right-justified binary
    ("TR_PROGRAMMABLE", {}, 100, 1, 4096, (100 << 12) | 1, 24),
])
def test_family_frame_layout(family, overrides, turns, step, spr, bits, length) -> None:
    """Each family's frame for a known position, bit for bit, as drawn in the manual."""
    enc = make_encoder(family, _at(turns, step, spr), **overrides)
    frame = enc.frame_at(0.0)
    assert frame.length == length == enc.frame_bits
    assert frame.bits == bits, f"{family}: {frame.bits:0{length}b} != {bits:0{length}b}"
    assert frame.count == turns * spr + step


@pytest.mark.parametrize("family, steps, expect", [
    ("AHS36", 1500, 1499 << 3),          # 004 §3.1 non-binary: MSB-justified, zero fill
])
def test_lower_resolution_is_msb_justified(family: str, steps: int, expect: int) -> None:
    """004 §3.1: for resolutions below 14 bits, non-assigned bits are filled with 0."""
    enc = make_encoder(family, Still(1499.5 / steps), steps_per_rev=steps)
    assert enc.frame_at(0.0).bits >> 1 == expect


@pytest.mark.parametrize("family, count, frame_bits", [
    ("TTK70", 0xABCDE, 26),     # 004 §3.6: 24 position bits + 2 error bits
    ("KH53", 0x12345, 24),      # 004 §3.7: 24 position bits
])
def test_linear_families(family: str, count: int, frame_bits: int) -> None:
    """004 §3.6/§3.7: linear measuring systems, position in metres."""
    enc = make_encoder(family)
    enc.motion = Still((count + 0.5) * enc.measuring_step_m)
    f = enc.frame_at(0.0)
    assert enc.linear and f.length == frame_bits and f.count == count
    assert f.bits >> (frame_bits - 24) == count


def test_kh53_error_value() -> None:
    """004 §3.7: on an error the KH53 sends FFFFE hex."""
    enc = make_encoder("KH53", Still(0.01))
    enc.set_error()
    assert enc.frame_at(0.0).bits == 0xFFFFE


@pytest.mark.parametrize("family", ["AFS60S_PRO", "AFM60S_PRO"])
def test_safety_encoder_error_sends_all_ones(family: str) -> None:
    """004 §3.3: on an internal error the SSI channel outputs only 1, error bits set."""
    enc = make_encoder(family, Still(0.3))
    enc.set_error()
    f = enc.frame_at(0.0)
    assert f.bits == (1 << f.length) - 1 and f.error
    assert {SpecialBit.ERRDIG, SpecialBit.ERRSI, SpecialBit.ERRSYNC} <= f.flags


@pytest.mark.parametrize("family, bits", [("AHS36", [SpecialBit.ERROR]),
                                          ("AFS60", [SpecialBit.ERRSI]),
                                          ("TTK70", [SpecialBit.ERR_DISTANCE, SpecialBit.ERR_TEMPERATURE])])
def test_error_bits_are_sent(family: str, bits: list[SpecialBit]) -> None:
    """004 §2.3 / §3.x: error bits follow the position bits and report the error."""
    enc = make_encoder(family, Still(0.25))
    clean = enc.frame_at(0.0)
    enc.set_error(bits=set(bits))
    f = enc.frame_at(0.0)
    area, levels = split(enc.config, f.bits)
    assert all(levels[b] == 1 for b in bits)
    assert decode_area(enc.config, area) == clean.count    # position still sent (FLAGS)
    enc.set_error(False, bits=set(bits))
    assert enc.frame_at(0.0).bits == clean.bits


def test_atm60_shift_right_drops_lsb() -> None:
    """004 §3.4 SSI-SHIFT-RIGHT: shifted one position right, LSB lost, first bit 0."""
    plain = make_encoder("ATM60", _at(4095, 8191, 8192)).frame_at(0.0).bits
    shifted = make_encoder("ATM60", _at(4095, 8191, 8192), shift_right=True).frame_at(0.0).bits
    assert shifted == plain >> 1 and shifted >> 24 == 0


def test_atm60_non_binary_is_right_aligned_on_bit_24() -> None:
    """004 §3.4 round axis: non-binary resolution right aligned on the 24th bit, 200 µs."""
    cfg = family_config("ATM60", steps_per_rev=1000)
    assert cfg.alignment is Alignment.RIGHT and cfg.formation_period_s == 200e-6
    enc = make_encoder("ATM60", Still(2 + 0.5005), steps_per_rev=1000)
    assert enc.frame_at(0.0).bits == 2500 << 1
    shifted = make_encoder("ATM60", Still(2 + 0.5005), steps_per_rev=1000, shift_right=True)
    assert shifted.frame_at(0.0).bits == 2500           # right aligned on the 25th bit


def test_atm60_sync_mode_uses_fixed_tm() -> None:
    """004 §3.4: synchronous mode, tm fixed at 150 µs and pause > 150 µs."""
    cfg = family_config("ATM60", ssi_mode=SsiMode.SYNC)
    assert cfg.monoflop_s == 150e-6 and cfg.min_pause_s == 150e-6


def test_unknown_family() -> None:
    with pytest.raises(ConfigError):
        make_encoder("NOPE")


def test_all_families_build() -> None:
    for name in FAMILIES:
        assert make_encoder(name).frame_at(0.0).length >= 13
