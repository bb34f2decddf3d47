"""To the letter of the manuals: the codes each family offers, TR data bits and plain frames.

The expected lists are written here from the manuals, not from ``family_rules.py``:

* 000 ch. 1 (XN-1SSI, the GENERIC frame): "Gray code or binary code data transmission is
  possible" (Table 19 SSI_CODE_G/D: 0 binary, 1 Gray);
* 004 §3.1 AHS/AHM36: "SSI Code Type: Gray / Binary", "the value is either Gray-coded or
  binary-coded", in binary and in non-binary operating mode (Figures 5-9);
* 004 §3.4 ATM60/ATM90: "The various code types such as binary, Gray or Gray excess can be
  set for this";
* 001 §5.2.2 "Transmit code": Binary, Gray, BCD; §5.2.4.2 check sum: "28 Datenbits ohne
  SSI-Sonderbits im Binärcode";
* 003 (the PowerFail frame): "Coding (e.g. Gray code)";
* 004 §3.2, §3.3, §3.5, §3.6, §3.7 name no code: binary and Gray (004 §2.4 "preferentially
  use the Gray code"), any other only under ``code_outside_manual``;
* 001 §5.2.1 "Number of data bits": lower limit 6, upper limit 63; §5.2.4.1 "A
  synchronous-serial data transmission with No special format is min. 8 bits, or max. 36
  bits long".
"""

from __future__ import annotations

import re

import pytest

from ssi_bridge.exceptions import ConfigError
from ssi_bridge.protocol.codes import Code
from ssi_bridge.protocol.encoder_config import EncoderConfig, FrameFormat, SpecialBit
from ssi_bridge.protocol.families import FAMILIES, family_config
from ssi_bridge.protocol.family_rules import FAMILY_CODES, code_refusal
from ssi_bridge.protocol.settings import make_joints, station_settings

B, G, GX, BCD = Code.BINARY, Code.GRAY, Code.GRAY_EXCESS, Code.BCD
SILENT = ("AFS60", "AFM60_MULTI", "AFS60S_PRO", "AFM60S_PRO", "ARS60", "TTK70", "KH53")
OFFERED: dict[str, set[Code]] = {
    "GENERIC": {B, G},                                   # 000 ch. 1, Table 19
    "AHS36": {B, G}, "AHM36_MULTI": {B, G},              # 004 §3.1
    "ATM60": {B, G, GX}, "ATM90": {B, G, GX}, "ATM60_13_12": {B, G, GX},   # 004 §3.4
    "TR_PROGRAMMABLE": {B, G, BCD}, "TR_PARITY": {B, G, BCD},              # 001 §5.2.2
    "TR_CHECKSUM": {B},                                  # 001 §5.2.4.2
    "SSI25_POWERFAIL": {B, G},                           # 003
    **{family: {B, G} for family in SILENT},             # 004 §2.4, sections silent
}


def test_every_family_has_its_manual_list() -> None:
    assert set(FAMILY_CODES) == set(FAMILIES) == set(OFFERED)


@pytest.mark.parametrize("family", sorted(OFFERED))
@pytest.mark.parametrize("code", list(Code), ids=lambda c: c.value)
def test_a_family_takes_exactly_the_codes_its_manual_offers(family: str, code: Code) -> None:
    refusal = code_refusal(family, code)
    if code in OFFERED[family]:
        assert refusal is None
    else:
        offered = ", ".join(c.value for c in Code if c in OFFERED[family])
        assert refusal is not None and f"offered: {offered}" in refusal, refusal
        assert re.search(r"\b00[0-4]\b", refusal), f"no manual cited: {refusal}"


@pytest.mark.parametrize("family, overrides, section, offered", [
    # the findings: Gray-excess on TR / PowerFail / GENERIC, BCD on AFS60 and on a
    # non-binary AHM36 were accepted silently
    ("TR_PROGRAMMABLE", dict(code=GX, steps_per_rev=3600), "001 §5.2.2", "binary, gray, bcd"),
    ("TR_PARITY", dict(code=GX, steps_per_rev=3600), "001 §5.2.2", "binary, gray, bcd"),
    ("SSI25_POWERFAIL", dict(code=GX, steps_per_rev=3600), "003", "binary, gray"),
    ("GENERIC", dict(code=GX, steps_per_rev=3600), "000 ch. 1", "binary, gray"),
    ("AFS60", dict(code=BCD, steps_per_rev=1000), "004 §2.4", "binary, gray"),
    ("AHM36_MULTI", dict(code=BCD, steps_per_rev=1000, revolutions_numerator=16), "004 §3.1",
     "binary, gray"),
    ("AHM36_MULTI", dict(code=GX, steps_per_rev=3600), "004 §3.1", "binary, gray"),
    ("AHS36", dict(code=GX, steps_per_rev=3600), "004 §3.1", "binary, gray"),
    ("ATM60", dict(code=BCD, steps_per_rev=1000, revolutions_numerator=10), "004 §3.4",
     "binary, gray, gray_excess"),
    ("TR_CHECKSUM", dict(code=G), "001 §5.2.4.2", "offered: binary"),
])
def test_a_code_the_manual_does_not_offer_is_refused_with_the_list(family, overrides, section,
                                                                   offered) -> None:
    with pytest.raises(ConfigError) as info:
        family_config(family, **overrides)
    text = str(info.value)
    assert section in text and offered in text and overrides["code"].value in text, text


def test_code_outside_manual_only_where_the_section_names_no_code() -> None:
    # 004 §3.2 names no code for AFS60: BCD under the explicit parameter only
    cfg = family_config("AFS60", code=BCD, steps_per_rev=1000, code_outside_manual=True)
    assert cfg.code is BCD
    with pytest.raises(ConfigError, match="code_outside_manual allows"):
        family_config("AFS60", code=BCD, steps_per_rev=1000)
    # 004 §3.1 and 000 ch. 1 give a list: the parameter does not override it
    for family, code in (("AHS36", GX), ("GENERIC", BCD), ("TR_PROGRAMMABLE", GX)):
        with pytest.raises(ConfigError, match="not offered"):
            family_config(family, code=code, steps_per_rev=1000, code_outside_manual=True)


def test_the_offered_codes_build() -> None:
    # Gray-excess on an ATM60 in round-axis operation (non-binary resolution, 004 §3.4), BCD on
    # a TR encoder (001 §5.2.2)
    assert family_config("ATM60", code=GX, steps_per_rev=3600).code is GX
    assert family_config("TR_PROGRAMMABLE", code=BCD, steps_per_rev=1000,
                         revolutions_numerator=100).code is BCD


# -- TR: number of data bits (001 §5.2.1) and the plain frame (001 §5.2.4.1) ----------------
def _tr(data_bits: int, *specials: SpecialBit, **kw) -> EncoderConfig:
    # 64 steps (6 bits) so that any data bits >= 6 hold the value
    return family_config("TR_PROGRAMMABLE", steps_per_rev=4, revolutions_numerator=16,
                         data_bits=data_bits, special_bits=specials, **kw)


@pytest.mark.parametrize("data_bits", [1, 5, 64])
def test_tr_data_bits_outside_6_to_63_are_refused_in_the_manuals_words(data_bits) -> None:
    with pytest.raises(ConfigError) as info:
        _tr(data_bits, SpecialBit.CAM1, SpecialBit.CAM2)
    text = str(info.value)
    assert f"data_bits {data_bits}" in text
    assert "001 §5.2.1 'Number of data bits': lower limit 6, upper limit 63" in text, text


@pytest.mark.parametrize("data_bits, specials", [
    (7, ()), (6, (SpecialBit.CAM1,)),                                     # 7 bits
    (36, (SpecialBit.CAM1,)), (37, ()), (36, (SpecialBit.CAM1, SpecialBit.CAM2)),  # 37, 37, 38
    (38, (SpecialBit.CAM1, SpecialBit.CAM2)), (40, ()), (63, ()),         # 40, 40, 63
])
def test_tr_plain_frames_outside_8_to_36_bits_are_refused(data_bits, specials) -> None:
    with pytest.raises(ConfigError) as info:
        _tr(data_bits, *specials)
    text = str(info.value)
    assert f"a frame of {data_bits + len(specials)} bits" in text
    assert ("001 §5.2.4.1: 'A synchronous-serial data transmission with No special format is "
            "min. 8 bits, or max. 36 bits long'") in text, text


@pytest.mark.parametrize("data_bits, specials", [
    (6, (SpecialBit.CAM1, SpecialBit.CAM2)), (8, ()), (36, ()),
    (33, (SpecialBit.CAM1, SpecialBit.CAM2, SpecialBit.UP)),
])
def test_tr_plain_frames_of_8_to_36_bits_with_6_or_more_data_bits_build(data_bits,
                                                                        specials) -> None:
    assert _tr(data_bits, *specials).frame_bits == data_bits + len(specials)


def test_tr_data_bit_limits_hold_in_the_tr_formats_and_other_families_keep_theirs() -> None:
    # 26-bit + repeat (001 §5.2.4.3) is always 26 bits; 5 data bits are still too few
    with pytest.raises(ConfigError, match="001 §5.2.1"):
        EncoderConfig(name="TR", steps_per_rev=4, revolutions_numerator=8, data_bits=5,
                      frame_format=FrameFormat.REPEAT_26)
    assert EncoderConfig(name="TR", steps_per_rev=4, revolutions_numerator=16, data_bits=6,
                         frame_format=FrameFormat.REPEAT_26).frame_bits == 26
    assert family_config("TR_CHECKSUM").frame_bits == 43   # 28 + 15 check sum bits
    # a SICK frame is no TR frame: ARS60 13 bits, AHS36 15, AFM60 33 (004 §3.5, §3.1, §3.2)
    assert family_config("ARS60").frame_bits == 13
    assert family_config("AFM60_MULTI").frame_bits == 33
    # a hand-made layout (no family name) keeps only the general limits
    assert EncoderConfig(name="custom", steps_per_rev=32, revolutions_numerator=1,
                         data_bits=5).frame_bits == 5


# -- the parameter checks the node and the station share (settings.py) ----------------------
def test_the_joint_parameters_refuse_a_code_the_family_does_not_offer() -> None:
    with pytest.raises(ConfigError) as info:
        make_joints(["wrist"], {"wrist.family": "TR_CHECKSUM", "wrist.code": "gray"})
    text = str(info.value)
    assert text.startswith("wrist.code") and "offered: binary" in text and "001 §5.2.4.2" in text
    with pytest.raises(ConfigError, match="offered: binary"):
        station_settings({"joints": ["wrist"], "wrist.family": "tr_checksum",
                          "wrist.code": "gray"})
    joints = make_joints(["shoulder"], {"shoulder.family": "AFM60_MULTI", "shoulder.code": "gray"})
    assert joints[0].code == "gray"
