"""Comparators CMP1/CMP2 (000 chapter 1 "Comparison value 1, Comparison value 2" truth table,
process input STS_CMPx / FLAG_CMPx / REL_CMPx, process output EN_CMPx / CLR_CMPx)."""

from __future__ import annotations

import pytest

from ssi_bridge.protocol.images import CmpControl, CmpStatus, ProcessInput
from ssi_bridge.protocol.registers import Reg

C = CmpStatus
UNITS = [  # (register, EN, CLR, STS, FLAG, REL)
    (Reg.REG_CMP1, CmpControl.EN_CMP1, CmpControl.CLR_CMP1, C.STS_CMP1, C.FLAG_CMP1, C.REL_CMP1),
    (Reg.REG_CMP2, CmpControl.EN_CMP2, CmpControl.CLR_CMP2, C.STS_CMP2, C.FLAG_CMP2, C.REL_CMP2),
]


def assert_cmp(image: ProcessInput, mask: CmpStatus, expected: CmpStatus, step: str) -> None:
    got = image.cmp & mask
    assert got == expected, f"{step}: comparator bits {got!r}, expected {expected!r}"


@pytest.mark.parametrize("unit", UNITS, ids=["CMP1", "CMP2"])
def test_truth_table_sequence(reader, module, master, unit) -> None:
    reg, en, clr, sts, flag, rel = unit
    mask = sts | flag | rel
    module.write_register(reg, 100)
    reader.push(50).push(50).push(100).push(150).push(150).push(100).push(100).push(99).push(99)
    # EN_CMPx = 0: REL = STS = FLAG = 0 whatever the position
    assert_cmp(master.cycle(), mask, C(0), "disabled")
    # EN = 1, pos < cmp: REL = 0, STS = 0, FLAG = Z0 (0: no match yet)
    assert_cmp(master.control(en), mask, C(0), "pos < cmp")
    # pos = cmp: REL = 1, STS = 1, FLAG = 1
    assert_cmp(master.control(en), mask, sts | flag | rel, "pos = cmp")
    # pos > cmp: REL = 1, STS = 0, FLAG stays 1 (latched)
    assert_cmp(master.control(en), mask, flag | rel, "pos > cmp, flag latched")
    # CLR_CMPx = 1 while not matching resets the flag
    assert_cmp(master.control(en, clr), mask, rel, "cleared")
    # pos = cmp with CLR held: "Reset of FLAG_CMPx not possible when values match"
    assert_cmp(master.control(en, clr), mask, sts | flag | rel, "match with CLR held")
    assert_cmp(master.control(en), mask, sts | flag | rel, "still matching")
    # pos < cmp: REL = 0, STS = 0, FLAG still 1 until cleared
    assert_cmp(master.control(en), mask, flag, "pos < cmp after match")
    # disabling: everything 0
    assert_cmp(master.control(), mask, C(0), "disabled again")


def test_disabling_forgets_the_flag(reader, module, master) -> None:
    # 000: "If the comparator is inactive (EN_CMPx = 0), the signals ... are always zero"
    reader.push(0).push(0).push(5).push(5)
    assert master.control(CmpControl.EN_CMP1).cmp & C.FLAG_CMP1, "match at 0 = REG_CMP1"
    master.control()
    assert not master.control(CmpControl.EN_CMP1).cmp & C.FLAG_CMP1, "flag restarts after EN = 0"


def test_both_comparators_are_independent(reader, module, master) -> None:
    module.write_register(Reg.REG_CMP1, 10)
    module.write_register(Reg.REG_CMP2, 20)
    reader.push(20)
    image = master.control(CmpControl.EN_CMP1, CmpControl.EN_CMP2)
    assert image.cmp & (C.STS_CMP1 | C.FLAG_CMP1 | C.REL_CMP1) == C.REL_CMP1
    assert image.cmp & (C.STS_CMP2 | C.FLAG_CMP2 | C.REL_CMP2) == C.STS_CMP2 | C.FLAG_CMP2 | C.REL_CMP2


@pytest.mark.parametrize("encoder, offset, cmp, rel", [
    (5, 10, 0, False),              # REG_SSI_POS = -5 < 0 (Integer32)
    (5, 10, 0xFFFFFFFB, True),      # -5 >= -5
    (0, 0, 0x80000000, True),       # 0 >= INT32_MIN
    (0x7FFFFFFF, 0, 0x80000000, True),
])
def test_comparison_is_signed(reader, module, master, encoder, offset, cmp, rel) -> None:
    # docs/module.md "Sign": comparisons as Integer32 (object 0x6820 is Integer32)
    module.write_para1(0x20010000)  # 32-bit frame
    module.write_register(Reg.REG_OFFSET, offset)
    module.write_register(Reg.REG_CMP1, cmp)
    reader.push(encoder)
    image = master.control(CmpControl.EN_CMP1)
    assert bool(image.cmp & C.REL_CMP1) == rel, f"pos {module.ssi_pos:#x} vs cmp {cmp:#x}"
