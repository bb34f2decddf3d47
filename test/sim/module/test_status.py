"""Limits (000 Tables 1 and 2), direction STS_UP/STS_DN (process input byte 6) and
REG_SSI_MASK status bits (000 Table 3)."""

from __future__ import annotations

import pytest

from ssi_bridge.sim.module.acquisition import direction
from ssi_bridge.protocol.diagnostics import Diag
from ssi_bridge.protocol.images import CmpStatus, ModuleStatus
from ssi_bridge.protocol.registers import Reg

M = ModuleStatus


#: each limit: its register, the status bit and diagnostics bit it sets, the table of 000 that
#: states it, the assertion message (pos, limit) and the diagnostics bit's text (000 Table 27)
LIMITS = {
    "upper": (Reg.REG_UPPER_LIMIT, M.STS_OFLW, Diag.STS_OFLW, "Table 1: pos {} upper {:#x}",
              "diagnostics bit 2 'Encoder value overflow'"),
    "lower": (Reg.REG_LOWER_LIMIT, M.STS_UFLW, Diag.STS_UFLW, "Table 2: pos {} lower {}",
              "diagnostics bit 3 'Encoder value underflow'"),
}


@pytest.mark.parametrize("side, limit, pos, hit", [
    ("upper", 0xFFFFFFFF, 0x1FFFFFF, False),   # Table 1: default -> STS_OFLW = 0
    ("upper", 1000, 1000, False), ("upper", 1000, 1001, True), ("upper", 1000, 0, False),
    ("lower", 0, 0, False),                    # Table 2: default -> STS_UFLW = 0
    ("lower", 100, 100, False), ("lower", 100, 99, True), ("lower", 100, 5000, False)])
def test_limits_tables_1_and_2(reader, module, master, side, limit, pos, hit) -> None:
    reg, sts_bit, diag_bit, table, diag_text = LIMITS[side]
    module.write_register(reg, limit)
    reader.push(pos)
    image = master.cycle()
    assert bool(image.sts & sts_bit) == hit, table.format(pos, limit)
    assert (diag_bit in module.diag) == hit, diag_text


@pytest.mark.parametrize("upper, lower, pos, oflw, uflw", [
    # 000 Table 1 "Register content of REG_UPPER_LIMIT less than FFFFFFFF hex": 0xFFFFFFFE is
    # an active upper limit far above 8192 (unsigned), not -2
    (0xFFFFFFFE, 0, 8192, False, False),
    # 000 Table 2 "Register content of REG_LOWER_LIMIT greater than 0": 0x80000000 is above
    # 8192 (unsigned), not INT32_MIN, so 8192 lies below it
    (0xFFFFFFFF, 0x80000000, 8192, False, True),
])
def test_limits_compare_unsigned(reader, module, master, upper, lower, pos, oflw, uflw) -> None:
    # 000 "Lower limit, upper limit": "The limit values are set by default to the maximum and
    # minimum value" (defaults 0xFFFFFFFF and 0: maximum and minimum as unsigned numbers)
    module.write_register(Reg.REG_UPPER_LIMIT, upper)
    module.write_register(Reg.REG_LOWER_LIMIT, lower)
    reader.push(pos)
    image = master.cycle()
    assert bool(image.sts & M.STS_OFLW) == oflw
    assert bool(image.sts & M.STS_UFLW) == uflw
    assert (Diag.STS_OFLW in module.diag, Diag.STS_UFLW in module.diag) == (oflw, uflw)


def test_position_below_the_offset_is_above_an_upper_limit(reader, module, master) -> None:
    # REG_SSI_POS = 9 - 10 = 0xFFFFFFFF (000 "Offset function": SSI encoder - REG_OFFSET), as
    # an Unsigned32 register above the upper limit 1000 and not below the lower limit 1
    module.write_register(Reg.REG_OFFSET, 10)
    module.write_register(Reg.REG_LOWER_LIMIT, 1)
    module.write_register(Reg.REG_UPPER_LIMIT, 1000)
    reader.push(9)
    sts = master.cycle().sts
    assert sts & M.STS_OFLW and not sts & M.STS_UFLW


@pytest.mark.parametrize("values, expected", [
    ([10, 11], (True, False)), ([10, 9], (False, True)), ([10, 10], (False, False))])
def test_direction_bits(reader, master, values, expected) -> None:
    # 000 process input STS_UP / STS_DN: both 0 when the value is constant
    for v in values:
        reader.push(v)
    master.cycle()
    image = master.cycle()
    assert (bool(image.cmp & CmpStatus.STS_UP), bool(image.cmp & CmpStatus.STS_DN)) == expected


@pytest.mark.parametrize("prev, cur, width, expected", [
    (None, 5, 25, (False, False)), ((1 << 25) - 1, 0, 25, (True, False)),
    (0, (1 << 25) - 1, 25, (False, True)), (3, 3, 8, (False, False))])
def test_direction_wraps_modulo_the_value_width(prev, cur, width, expected) -> None:
    # a multiturn roll-over max -> 0 is one step up (docs/module.md "Direction")
    assert direction(prev, cur, width) == expected


def test_direction_is_zero_while_stopped(reader, master) -> None:
    reader.push(1).push(2).push(3)
    master.cycle()
    assert master.cycle().cmp & CmpStatus.STS_UP
    assert not master.cycle(stop=True).cmp & (CmpStatus.STS_UP | CmpStatus.STS_DN)


@pytest.mark.parametrize("mask, frame, ssi_sts, ssi_diag", [
    (0x00000000, 0x1FFFFFF, 0b0000, False),   # default: nothing transferred
    (0x00000080, 0x0000001, 0b0001, False),   # EN_D0_RMS0, bit 0 -> SSI_STS0
    (0x000000C0, 0x0000001, 0b0001, True),    # + EN_D0_DS -> SSI_DIAG
    (0x00000040, 0x0000001, 0b0000, False),   # DS without RMS: SSI_STS0 = 0, so no DIAG
    (0x98000000, 0x1000000, 0b1000, False),   # byte 3: bit 24 -> SSI_STS3
    (0xD8000000, 0x1000000, 0b1000, True),
    (0x00C28100, 0x0000006, 0b0110, True),    # STS1 <- bit 1, STS2 <- bit 2 (DS)
    (0x0000009F, 0x1FFFFFF, 0b0000, False),   # bit 31 beyond a 25-bit frame reads 0
])
def test_ssi_mask_table_3(reader, module, master, mask, frame, ssi_sts, ssi_diag) -> None:
    # 000 Table 3 and SSI_DIAG = OR (SSI_STSx & EN_Dx_DS)
    module.write_register(Reg.REG_SSI_MASK, mask)
    reader.push(frame)
    image = master.cycle()
    assert image.ssi_sts == ssi_sts, f"mask {mask:#010x} frame {frame:#x}: {image.ssi_sts:04b}"
    assert bool(image.sts & M.SSI_DIAG) == ssi_diag
    assert (Diag.SSI_DIAG in module.diag) == ssi_diag, "diagnostics bit 0 SSI group diagnostics"
