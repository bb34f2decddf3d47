"""Register table, access rules and REG_PARA1 fields (000 "Register access and meaning",
the interface table after it, Tables 18 and 19)."""

from __future__ import annotations

import pytest

from ssi_bridge.exceptions import ParameterError, RegisterReadError, RegisterWriteError
from ssi_bridge.protocol.registers import (
    BIT_RATES_HZ, MAGIC_NO, PARA1_DEFAULT, REGISTERS, RETENTIVE, Para1, Reg, describe_refusal,
    validate_para1,
)
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

NAMED = {int(r) for r in Reg}
RESERVED = [a for a in range(64) if a not in NAMED]


# 000 "Register access and meaning": addresses and names
@pytest.mark.parametrize("reg, addr", [
    (Reg.REG_SSI_POS, 0), (Reg.REG_MAGIC_NO, 1), (Reg.REG_HW_VER, 2), (Reg.REG_SW_VER, 3),
    (Reg.REG_SF, 4), (Reg.REG_WR_ADR, 14), (Reg.REG_RD_ADR, 15), (Reg.REG_DIAG1, 16),
    (Reg.REG_PARA1, 20), (Reg.REG_GRAY_POS, 32), (Reg.REG_SSI_FRAME, 33), (Reg.REG_CMP1, 34),
    (Reg.REG_CMP2, 35), (Reg.REG_LOWER_LIMIT, 48), (Reg.REG_UPPER_LIMIT, 49),
    (Reg.REG_OFFSET, 50), (Reg.REG_SSI_MASK, 51),
])
def test_register_addresses_follow_the_register_table(reg: Reg, addr: int) -> None:
    assert int(reg) == addr, f"000 register table: {reg.name} is register {addr}"


def test_reserved_addresses_are_the_reserve_rows() -> None:
    # 000 register table: "REG 5..13, 17..19, 21..31, 36..47, 52..63 Reserve"
    expected = [*range(5, 14), *range(17, 20), *range(21, 32), *range(36, 48), *range(52, 64)]
    assert RESERVED == expected, "000 register table Reserve rows"


# 000 interface table: process output WR / storage / process input RD / parameter interface
@pytest.mark.parametrize("reg, writable, retentive", [
    (Reg.REG_SSI_POS, False, False), (Reg.REG_MAGIC_NO, False, False),
    (Reg.REG_HW_VER, False, False), (Reg.REG_SW_VER, False, False), (Reg.REG_SF, True, False),
    (Reg.REG_WR_ADR, False, False), (Reg.REG_RD_ADR, False, False), (Reg.REG_DIAG1, False, False),
    (Reg.REG_PARA1, True, True), (Reg.REG_GRAY_POS, False, False),
    (Reg.REG_SSI_FRAME, False, False), (Reg.REG_CMP1, True, False), (Reg.REG_CMP2, True, False),
    (Reg.REG_LOWER_LIMIT, True, True), (Reg.REG_UPPER_LIMIT, True, True),
    (Reg.REG_OFFSET, True, True), (Reg.REG_SSI_MASK, True, True),
])
def test_access_table(reg: Reg, writable: bool, retentive: bool) -> None:
    row = REGISTERS[reg]
    assert row.readable, f"000 interface table: {reg.name} is RD via process input"
    assert row.writable == writable, f"000 interface table: {reg.name} WR = {writable}"
    assert row.retentive == retentive, f"000 interface table: {reg.name} retentive = {retentive}"
    assert row.parameter == (reg is Reg.REG_PARA1), "only REG_PARA1 has the parameter interface"
    assert row.diagnostics == (reg is Reg.REG_DIAG1), "only REG_DIAG1 is on the diagnostics interface"


def test_retentive_registers() -> None:
    # 000 interface table "Storage in module: Retentive"
    assert RETENTIVE == (Reg.REG_PARA1, Reg.REG_LOWER_LIMIT, Reg.REG_UPPER_LIMIT,
                         Reg.REG_OFFSET, Reg.REG_SSI_MASK)


@pytest.mark.parametrize("reg, default", [
    (Reg.REG_PARA1, 0x19010000), (Reg.REG_CMP1, 0), (Reg.REG_CMP2, 0),
    (Reg.REG_LOWER_LIMIT, 0), (Reg.REG_UPPER_LIMIT, 0xFFFFFFFF), (Reg.REG_OFFSET, 0),
    (Reg.REG_SSI_MASK, 0), (Reg.REG_MAGIC_NO, 0xAA55CC33), (Reg.REG_SF, 0),
])
def test_defaults_read_back_from_a_fresh_module(reg: Reg, default: int) -> None:
    # 000 register table "Default (HEX)"
    assert Xn1Ssi().read_register(reg) == default, f"000 default of {reg.name}"
    assert MAGIC_NO == 0xAA55CC33


@pytest.mark.parametrize("addr, write, reason", [
    (5, True, "reserved"), (13, False, "reserved"), (63, True, "reserved"),
    (64, False, "out of range 0..63"), (255, True, "out of range 0..63"),
    (-1, False, "out of range 0..63"), (0, True, "read-only"), (1, True, "read-only"),
    (16, True, "read-only"), (32, True, "read-only"), (33, True, "read-only"),
    (14, True, "read-only"), (15, True, "read-only"),
    (20, True, None), (4, True, None), (0, False, None), (51, False, None),
])
def test_describe_refusal(addr: int, write: bool, reason: str | None) -> None:
    # 000 interface table: RD/WR columns and the Reserve rows
    assert describe_refusal(addr, write) == reason, f"address {addr} write={write}"


@pytest.mark.parametrize("addr", [*RESERVED, 64, 100, 255])
def test_api_read_refuses_reserved_and_out_of_range(addr: int) -> None:
    # 000 "Internal registers": REG_RD_ABORT = 1 when the register cannot be read
    with pytest.raises(RegisterReadError) as err:
        Xn1Ssi().read_register(addr)
    assert err.value.address == addr
    assert err.value.reason in ("reserved", "out of range 0..63"), str(err.value)


@pytest.mark.parametrize("addr, reason", [(0, "read-only"), (2, "read-only"), (7, "reserved"),
                                          (64, "out of range 0..63"), (200, "out of range 0..63")])
def test_api_write_refusals_name_the_reason(addr: int, reason: str) -> None:
    # 000 "Internal registers": REG_WR_ACCEPT = 0 "no access authorisation, out of value range"
    with pytest.raises(RegisterWriteError) as err:
        Xn1Ssi().write_register(addr, 1)
    assert err.value.reason == reason, str(err.value)
    assert f"0x{addr:02X}" in str(err.value), "message carries the address in hex"


@pytest.mark.parametrize("value", [-1, 1 << 32, 2**40])
def test_api_write_value_out_of_range(value: int) -> None:
    with pytest.raises(RegisterWriteError, match="out of range"):
        Xn1Ssi().write_register(Reg.REG_CMP1, value)


# 000 Tables 18/19 (REG_PARA1 fields)
@pytest.mark.parametrize("value, expected", [
    (0x19010000, Para1(25, 1, 0, 0, False, False)),
    (0x99010000, Para1(25, 1, 0, 0, True, False)),
    (0x20070000 | 0x7F00 | 0x20, Para1(32, 7, 7, 15, False, True)),
    (0x01000000, Para1(1, 0, 0, 0, False, False)),
    (0x0D023120, Para1(13, 2, 3, 1, False, True)),
])
def test_para1_decode_encode(value: int, expected: Para1) -> None:
    assert Para1.decode(value) == expected, f"Table 18 fields of 0x{value:08X}"
    assert expected.encode() == value, "encode is the inverse of decode"


def test_para1_default() -> None:
    # 000 register table: REG_PARA1 default 0x19 01 00 00 = 25 bit, 500 kBit/s, binary
    para = Para1.decode(PARA1_DEFAULT)
    assert (para.ssi_frame_len, para.bit_rate_hz, para.ssi_code_gray) == (25, 500_000, False)
    assert validate_para1(PARA1_DEFAULT) is None


@pytest.mark.parametrize("code, hz", [(0, 1_000_000), (1, 500_000), (2, 250_000), (3, 125_000),
                                      (4, 100_000), (5, 83_000), (6, 71_000), (7, 62_500)])
def test_bit_rates(code: int, hz: int) -> None:
    # 000 Table 19 SSI_BIT_RATE (and the PROFIBUS-DP parameter table)
    assert BIT_RATES_HZ[code] == hz


@pytest.mark.parametrize("value, fragment", [
    (0x00010000, "SSI_FRAME_LEN = 0 must be 1..32"),
    (0x21010000, "SSI_FRAME_LEN = 33 must be 1..32"),
    (0x3F010000, "SSI_FRAME_LEN = 63"),
    (0x19080000, "SSI_BIT_RATE = 8 is reserved"),
    (0x190F0000, "SSI_BIT_RATE = 15 is reserved"),
    (0x08017100, "INVALID_BITS_MSB + INVALID_BITS_LSB = 8 must be < SSI_FRAME_LEN = 8"),
    (0x16017F00, "INVALID_BITS_MSB + INVALID_BITS_LSB = 22 must be < SSI_FRAME_LEN = 22"),
    (0x19010001, "reserved bits 0x00000001"),
    (0x59010000, "reserved bits 0x40000000"),
])
def test_para1_invalid_sets(value: int, fragment: str) -> None:
    # 000 Table 19: ranges; "INVALID_BITS_MSB + INVALID_BITS_LSB must always be less than SSI_FRAME_LEN"
    problem = validate_para1(value)
    assert problem is not None and fragment in problem, f"0x{value:08X}: {problem!r}"
    with pytest.raises(ParameterError) as err:
        Xn1Ssi().write_para1(value)
    assert fragment in err.value.reason


@pytest.mark.parametrize("value", [0x16017E00, 0x01000000, 0x20000000, 0x99070000 | 0x20])
def test_para1_valid_sets(value: int) -> None:
    assert validate_para1(value) is None, f"0x{value:08X} is a valid Table 19 set"


def test_injected_parameter_error_until_a_valid_set(module, reader) -> None:
    # 000 "Error detection": ERR_PARA is a "non-retentive error message, and rejected
    # parameter set with it"; STS_STOP = 1 while it stands; a valid set clears it
    from ssi_bridge.protocol.images import ModuleStatus
    reason = module.inject_parameter_error()
    assert "reserved" in reason
    module.cycle(0.0)
    assert module.status.sts & ModuleStatus.ERR_PARA and module.status.sts & ModuleStatus.STS_STOP
    module.clear_parameter_error()
    module.cycle(0.001)
    assert not module.status.sts & (ModuleStatus.ERR_PARA | ModuleStatus.STS_STOP)
    with pytest.raises(ValueError):
        module.inject_parameter_error(0x19010000)   # a valid set cannot raise ERR_PARA
