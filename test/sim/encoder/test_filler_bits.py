"""Filler bits and justification in every code a family offers, for every family (004 §2.4,
§3; 001 §5.2). A code a family's manual does not offer is refused (test_family_rules.py); the
families whose 004 section names no code are also checked in Gray-excess and BCD, which they
take only under ``code_outside_manual``.

The expected frames are built here, as bit strings, from the layout rules the manuals state,
without the project's layout code:

* 004 SICK SSI description, §3.1 AHS/AHM36: "Non-programmable encoders always output the SSI
  position MSB-justified (left-justified)." / "For resolutions below 14 bits, non-assigned bits
  are filled with 0." / "-> Zero Bit: At lower resolution, the transmission frame is filled
  with zero bits." / multiturn: "26 bits + 1 error bit are always output ... For resolutions
  below 26 bits, non-assigned bits are filled with 0." / "In binary operating mode, the
  multiposition is transmitted separately from the single position."
* 004 §3.2 AFS/AFM60: "If the absolute value encoder is set to a resolution of 13 bits, then
  16 bits are output: 13 data bits and 3 error bits." (the error bits follow the position).
* 004 §3.4 ATM60: "The so called Tannenbaum format for transmitting the position is
  permanently set. This means that when a lower resolution is set, the MSB or LSB side is
  filled with "0"" / non-binary: "only a right aligned output on the 24th bit (bit shift
  right=0)" / "The various code types such as binary, Gray or Gray excess can be set for this."
* 004 §3.5 ARS60: 13 singleturn bits up to 8192 steps; 15 bits + 2 error bits above.
* 004 §3.6 TTK70: "Clock 1-24: Position bits", "Clock 25-26: Error bits"; §3.7 KH53: 24 bits.
* 001 TR manual §5.2.4.1: "Leading "zeros" are produced if the parameter Number of data bits
  is programmed larger, as it would be necessary from the total measuring length."
* 004 §2.4 Table 1 (binary, BCD, Gray columns) and "Gray excess code": "a suitable section
  ... extracted from the middle of the full Gray code".

A filler bit is never part of a code word: the word is formed from the value in as many bits
as the value needs and then placed, so in Gray code too the non-assigned bits are 0.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import pytest

from ssi_bridge.protocol.codes import Code
from ssi_bridge.sim.encoder.encoder import make_encoder
from ssi_bridge.sim.encoder.motion import Still


# -- reference codes, from 004 §2.4 ---------------------------------------------------------
def ref_binary(value: int, width: int) -> str:
    return format(value, f"0{width}b")


def ref_gray(value: int, width: int) -> str:
    """Reflected binary code: first bit as in binary, every other bit = b[i-1] XOR b[i]."""
    b = ref_binary(value, width)
    return b[0] + "".join("1" if b[i - 1] != b[i] else "0" for i in range(1, width))


def ref_bcd(value: int, width: int) -> str:
    """One 4-bit binary group per decimal digit (004 §2.4 Table 1 BCD column)."""
    digits = "".join(ref_binary(int(d), 4) for d in str(value))
    return digits.rjust(width, "0")


def ref_gray_excess(value: int, resolution: int) -> str:
    """The ``resolution`` codes centred in the full N-bit Gray code (004 §2.4)."""
    n = (resolution - 1).bit_length()
    return ref_gray(value + ((1 << n) - resolution) // 2, n)


def test_reference_codes_match_the_manual_table() -> None:
    """004 §2.4 Table 1: the reference helpers reproduce the printed rows 0..15."""
    gray = ["0000", "0001", "0011", "0010", "0110", "0111", "0101", "0100",
            "1100", "1101", "1111", "1110", "1010", "1011", "1001", "1000"]
    bcd = ["0000000", "0000001", "0000010", "00000011", "00000100", "00000101", "00000110",
           "00000111", "00001000", "00001001", "00010000", "00010001", "00010010",
           "00010011", "00010100", "00010101"]
    for v in range(16):
        assert ref_gray(v, 4) == gray[v]
        assert int(ref_bcd(v, 8), 2) == int(bcd[v], 2)


def code_word(code: Code, value: int, bits: int, resolution: int) -> str:
    """The code word of ``value`` in the ``bits`` the value range needs."""
    if code is Code.BINARY:
        return ref_binary(value, bits)
    if code is Code.GRAY:
        return ref_gray(value, bits)
    if code is Code.BCD:
        return ref_bcd(value, bits)
    return ref_gray_excess(value, resolution)


# -- layouts, as the manuals draw them -------------------------------------------------------
@dataclass(frozen=True)
class Layout:
    """Where the position goes: ``msb`` / ``right`` in ``width`` clocks, or Tannenbaum."""

    kind: str               # "msb", "right", "tannenbaum"
    width: int              # clocks of the position area (before trailing zero clocks)
    trailing_zeros: int = 0  # ATM60 non-binary: right aligned on the 24th bit of 25
    turn_bits: int = 0      # Tannenbaum: multiturn clocks (the rest is singleturn)
    error_bits: int = 0     # error / special clocks after the position (all 0 here)


@dataclass(frozen=True)
class Case:
    family: str
    code: Code
    overrides: dict
    steps_per_rev: int      # steps per revolution (rotary) or 0 (linear)
    revolutions: int        # revolutions in the range (1 = singleturn)
    layout: Layout
    total: int = 0          # linear: total steps

    @property
    def resolution(self) -> int:
        return self.total or self.steps_per_rev * self.revolutions

    def value_bits(self) -> int:
        top = self.resolution - 1
        return 4 * len(str(top)) if self.code is Code.BCD else top.bit_length()


def expected_frame(case: Case, value: int) -> str:
    """The frame of ``value`` built from the layout rules (004 §3, 001 §5.2.4.1)."""
    lay = case.layout
    if lay.kind == "tannenbaum":
        # 004 §3.4: multiturn right-justified in its clocks (MSB side 0), singleturn
        # MSB-justified in its clocks (LSB side 0); Gray over the whole value (one bit per step)
        n = case.steps_per_rev.bit_length() - 1
        word = code_word(case.code, value, lay.turn_bits + n, case.resolution)
        turns, steps = word[:lay.turn_bits], word[lay.turn_bits:]
        st_clocks = lay.width - lay.turn_bits
        area = turns + steps.ljust(st_clocks, "0")
    else:
        word = code_word(case.code, value, case.value_bits(), case.resolution)
        area = word.ljust(lay.width, "0") if lay.kind == "msb" else word.rjust(lay.width, "0")
    return area + "0" * lay.trailing_zeros + "0" * lay.error_bits


B, G, GX, BCD = Code.BINARY, Code.GRAY, Code.GRAY_EXCESS, Code.BCD
#: a family whose 004 section names no code takes Gray-excess / BCD only under this
#: explicit parameter (protocol/family_rules.py); the codes a family's manual does not
#: offer are refused (test_family_rules.py), so they have no row here
OUTSIDE = {"code_outside_manual": True}
ST = dict(revolutions_numerator=1)
AHS36 = Layout("msb", 14, error_bits=1)                     # 004 §3.1 clocks 1-14, 15
AHM36_BIN = Layout("tannenbaum", 26, turn_bits=12, error_bits=1)  # 004 §3.1 clocks 1-12, 13-26
AHM36_MSB = Layout("msb", 26, error_bits=1)                 # non-binary: MSB-justified
ATM60_BIN = Layout("tannenbaum", 25, turn_bits=12)          # 004 §3.4 Figure 18
ATM60_1312 = Layout("tannenbaum", 25, turn_bits=13)         # 004 §3.4 Figure 17
ATM60_RA = Layout("right", 24, trailing_zeros=1)            # 004 §3.4 right aligned on 24th bit

#: AFS60 (004 §3.2): position bits directly followed by 3 error bits
AFS60_CASES = [
    Case("AFS60", B, {"steps_per_rev": 8192}, 8192, 1, Layout("msb", 13, error_bits=3)),
    Case("AFS60", G, {"steps_per_rev": 8192}, 8192, 1, Layout("msb", 13, error_bits=3)),
    Case("AFS60", GX, {**OUTSIDE, "steps_per_rev": 3600}, 3600, 1,
         Layout("msb", 12, error_bits=3)),
    Case("AFS60", BCD, {**OUTSIDE, "steps_per_rev": 1000}, 1000, 1,
         Layout("msb", 12, error_bits=3)),
]
#: AFM60 (004 §3.2): 12 multiturn + singleturn bits + 3 error bits
AFM60_CASES = [
    Case("AFM60_MULTI", B, {"steps_per_rev": 8192}, 8192, 4096,
         Layout("tannenbaum", 25, turn_bits=12, error_bits=3)),
    Case("AFM60_MULTI", G, {"steps_per_rev": 8192}, 8192, 4096,
         Layout("tannenbaum", 25, turn_bits=12, error_bits=3)),
    Case("AFM60_MULTI", GX, {**OUTSIDE, "steps_per_rev": 3600}, 3600, 4096,
         Layout("msb", 24, error_bits=3)),
    Case("AFM60_MULTI", BCD, {**OUTSIDE, "steps_per_rev": 1000, "revolutions_numerator": 10,
                              "data_bits": 24}, 1000, 10, Layout("msb", 24, error_bits=3)),
]


def as_family(family: str, cases: list[Case]) -> list[Case]:
    """The same rows for another family whose frames are the same."""
    return [dataclasses.replace(c, family=family) for c in cases]


CASES = [
    # GENERIC: the XN-1SSI default frame, 25 clocks right-justified
    Case("GENERIC", B, {"steps_per_rev": 4096}, 4096, 4096, Layout("right", 25)),
    Case("GENERIC", G, {"steps_per_rev": 4096}, 4096, 4096, Layout("right", 25)),
    # AHS36 (004 §3.1): the example of a 12-bit resolution in 14 clocks
    Case("AHS36", B, {"steps_per_rev": 4096}, 4096, 1, AHS36),
    Case("AHS36", G, {"steps_per_rev": 4096}, 4096, 1, AHS36),
    # AHM36 multiturn (004 §3.1): binary = Tannenbaum, non-binary = MSB-justified in 26
    Case("AHM36_MULTI", B, {"steps_per_rev": 4096}, 4096, 4096, AHM36_BIN),
    Case("AHM36_MULTI", G, {"steps_per_rev": 4096}, 4096, 4096, AHM36_BIN),
    Case("AHM36_MULTI", B, {"steps_per_rev": 3600}, 3600, 4096, AHM36_MSB),
    Case("AHM36_MULTI", G, {"steps_per_rev": 3000, "revolutions_numerator": 16}, 3000, 16,
         AHM36_MSB),
    *AFS60_CASES,
    *AFM60_CASES,
    # AFS/AFM60S Pro (004 §3.3): as AFS/AFM60 while healthy
    *as_family("AFS60S_PRO", AFS60_CASES),
    *as_family("AFM60S_PRO", AFM60_CASES),
    # ATM60 (004 §3.4): Tannenbaum with a lower resolution, or right aligned on the 24th bit
    Case("ATM60", B, {"steps_per_rev": 4096, "revolutions_numerator": 1024}, 4096, 1024,
         ATM60_BIN),
    Case("ATM60", G, {"steps_per_rev": 4096, "revolutions_numerator": 1024}, 4096, 1024,
         ATM60_BIN),
    Case("ATM60", GX, {"steps_per_rev": 3600, "revolutions_numerator": 1024}, 3600, 1024,
         ATM60_RA),
    Case("ATM60_13_12", B, {"steps_per_rev": 2048, "revolutions_numerator": 4096}, 2048, 4096,
         ATM60_1312),
    Case("ATM60_13_12", G, {"steps_per_rev": 2048, "revolutions_numerator": 4096}, 2048, 4096,
         ATM60_1312),
    Case("ATM60_13_12", GX, {"steps_per_rev": 3000, "revolutions_numerator": 4096}, 3000, 4096,
         ATM60_RA),
    # ARS60 (004 §3.5): 13 bits up to 8192 steps (MSB-justified, docs/encoder_line.md)
    Case("ARS60", B, {"steps_per_rev": 4096}, 4096, 1, Layout("msb", 13)),
    Case("ARS60", G, {"steps_per_rev": 4096}, 4096, 1, Layout("msb", 13)),
    Case("ARS60", GX, {**OUTSIDE, "steps_per_rev": 3600}, 3600, 1, Layout("msb", 13)),
    Case("ARS60", BCD, {**OUTSIDE, "steps_per_rev": 1000}, 1000, 1, Layout("msb", 13)),
    Case("ARS60", G, {"steps_per_rev": 16384}, 16384, 1, Layout("msb", 15, error_bits=2)),
    # TTK70 (004 §3.6): 24 position bits + 2 error bits; KH53 (§3.7): 24 bits
    Case("TTK70", B, {"total_steps": 1 << 20}, 0, 1, Layout("right", 24, error_bits=2),
         total=1 << 20),
    Case("TTK70", G, {"total_steps": 1 << 20}, 0, 1, Layout("right", 24, error_bits=2),
         total=1 << 20),
    Case("TTK70", GX, {**OUTSIDE, "total_steps": 1_000_000}, 0, 1,
         Layout("right", 24, error_bits=2),
         total=1_000_000),
    Case("TTK70", BCD, {**OUTSIDE, "total_steps": 10_000}, 0, 1, Layout("right", 24, error_bits=2),
         total=10_000),
    Case("KH53", B, {"total_steps": 1 << 20}, 0, 1, Layout("right", 24), total=1 << 20),
    Case("KH53", G, {"total_steps": 1 << 20}, 0, 1, Layout("right", 24), total=1 << 20),
    Case("KH53", GX, {**OUTSIDE, "total_steps": 1_000_000}, 0, 1,
         Layout("right", 24), total=1_000_000),
    Case("KH53", BCD, {**OUTSIDE, "total_steps": 10_000}, 0, 1, Layout("right", 24), total=10_000),
    # TR (001 §5.2.4.1): Number of data bits larger than needed -> leading zeros
    Case("TR_PROGRAMMABLE", B, {"data_bits": 26}, 4096, 4096, Layout("right", 26)),
    Case("TR_PROGRAMMABLE", G, {"data_bits": 26}, 4096, 4096, Layout("right", 26)),
    Case("TR_PROGRAMMABLE", BCD, {"data_bits": 26, "steps_per_rev": 1000,
                                  "revolutions_numerator": 100}, 1000, 100,
         Layout("right", 26)),
]


def _encoder(case: Case, value: int):
    """Encoder of ``case`` resting in the middle of step ``value`` (rotary or linear)."""
    overrides = {"code": case.code, **case.overrides}
    if case.total:
        step_m = 1e-3
        return make_encoder(case.family, Still((value + 0.5) * step_m), measuring_step_m=step_m,
                            **overrides)
    return make_encoder(case.family, Still((value + 0.5) / case.steps_per_rev), **overrides)


def _values(case: Case) -> list[tuple[int, int]]:
    """(shaft step, expected value): 0, 1, max-1 and the wrap (max -> 0, max + 1 -> 1)."""
    r = case.resolution
    return [(0, 0), (1, 1), (r - 2, r - 2), (r - 1, r - 1), (r, 0), (r + 1, 1)]


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c.family}-{c.code.value}")
def test_frame_from_layout_rules(case: Case) -> None:
    """Every family x code: filler bits 0, MSB/right/Tannenbaum placement, wrap at the range."""
    lay = case.layout
    n_clocks = lay.width + lay.trailing_zeros + lay.error_bits
    for step, value in _values(case):
        frame = _encoder(case, step).frame_at(0.0)
        want = expected_frame(case, value)
        assert len(want) == n_clocks == frame.length
        got = format(frame.bits, f"0{frame.length}b")
        assert got == want, f"{case.family} {case.code.value} step {step}: {got} != {want}"
        assert frame.count == value


def test_issue_example_ahs36_gray_12_bits() -> None:
    """004 §3.1 l.169 "non-assigned bits are filled with 0": 12-bit Gray value 1 in 14 clocks.

    Gray(1) = 000000000001 (12 bits), MSB-justified in clocks 1-14, error bit 0 at clock 15.
    """
    enc = make_encoder("AHS36", Still(1.5 / 4096), steps_per_rev=4096, code=Code.GRAY)
    assert format(enc.frame_at(0).bits, "015b") == "000000000001000"


def test_gray_excess_is_msb_justified_on_ars60() -> None:
    """004 §3.5 (MSB-justified, docs/encoder_line.md), also in Gray-excess: a code 004 §3.5
    does not name, so only under ``code_outside_manual`` (AHS36 refuses it: 004 §3.1 offers
    Gray and binary, test_family_rules.py)."""
    enc = make_encoder("ARS60", Still(0.5 / 3600), steps_per_rev=3600, code=Code.GRAY_EXCESS,
                       code_outside_manual=True)
    e = (4096 - 3600) // 2   # 248: 3600 codes from the middle of the 12-bit Gray code
    assert format(enc.frame_at(0).bits, "013b") == ref_gray(e, 12) + "0"


@pytest.mark.parametrize("family, overrides, steps, revs", [
    ("ATM60", {}, 8192, 4096),
    ("AHM36_MULTI", {"steps_per_rev": 4096}, 4096, 4096),
])
def test_tannenbaum_gray_one_bit_per_step_across_a_revolution(family, overrides, steps,
                                                              revs) -> None:
    """004 §2.4: "only one bit changes when transitioning from one position value to the next",
    also from the last step of a revolution to the first of the next and at the wrap."""
    def frame(step: int) -> int:
        return make_encoder(family, Still((step + 0.5) / steps), code=Code.GRAY,
                            **overrides).frame_at(0).bits

    for a in (steps - 1, 5 * steps - 1, steps * revs - 1):
        assert bin(frame(a) ^ frame(a + 1)).count("1") == 1
