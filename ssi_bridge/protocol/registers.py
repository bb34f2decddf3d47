"""The 64-register bank of the XN-1SSI: names, access rules, defaults (000 chapter 1).

Sources: 000 "Register access and meaning" (names, addresses, defaults) and the interface
table after it (process output WR, storage in module, process input RD, parameter interface,
diagnostics interface).  Every address not named there (5-13, 17-19, 21-31, 36-47, 52-63) is
"Reserve".  Other stages use :func:`describe_refusal` to explain a refusal to a person.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from ssi_bridge.protocol.para1 import (  # re-exported: Para1 belongs to the register table
    BIT_RATES_HZ,
    DEVICENET_BIT_RATES_HZ,
    PARA1_DEFAULT,
    Para1,
    validate_para1,
)

__all__ = [
    "BIT_RATES_HZ", "DEVICENET_BIT_RATES_HZ", "PARA1_DEFAULT", "Para1", "validate_para1",
    "Reg", "RegisterInfo", "REGISTERS", "REGISTER_COUNT", "RETENTIVE", "PARAMETER_REGISTERS",
    "MAGIC_NO", "HW_VERSION", "SW_VERSION", "SF_LD20", "SF_LD48", "VALUE_MAX",
    "describe_refusal", "info",
]

#: number of register addresses (000 "Internal registers": "access to up to 64 registers")
REGISTER_COUNT = 64
#: largest register value (32 bit)
VALUE_MAX = 0xFFFFFFFF
#: REG_MAGIC_NO content (000 "Register access and meaning")
MAGIC_NO = 0xAA55CC33
#: REG_HW_VER / REG_SW_VER of the model (the manual gives no values; chosen, docs/module.md)
HW_VERSION = 0x00000001
SW_VERSION = 0x00000100
#: REG_SF signatures (000 "Resetting the register bank"): "LD20" incl. parameters, "LD48" without
SF_LD20 = 0x6C643230
SF_LD48 = 0x6C643438


class Reg(IntEnum):
    """Named register addresses (000 "Register access and meaning")."""

    REG_SSI_POS = 0
    REG_MAGIC_NO = 1
    REG_HW_VER = 2
    REG_SW_VER = 3
    REG_SF = 4
    REG_WR_ADR = 14
    REG_RD_ADR = 15
    REG_DIAG1 = 16
    REG_PARA1 = 20
    REG_GRAY_POS = 32
    REG_SSI_FRAME = 33
    REG_CMP1 = 34
    REG_CMP2 = 35
    REG_LOWER_LIMIT = 48
    REG_UPPER_LIMIT = 49
    REG_OFFSET = 50
    REG_SSI_MASK = 51


@dataclass(frozen=True)
class RegisterInfo:
    """One row of the 000 interface table."""

    #: readable via the process input (RD)
    readable: bool
    #: writable via the process output (WR)
    writable: bool
    #: "Storage in module": True = retentive (survives a restart), False = non-retentive
    retentive: bool
    #: writable via the parameter interface (only REG_PARA1)
    parameter: bool
    #: readable via the diagnostics interface (only REG_DIAG1)
    diagnostics: bool
    #: value after a restart or LD20/LD48 (000 "Default (HEX)"); 0 where none is given
    default: int
    #: the manual's description column
    description: str


def _row(rd: bool, wr: bool, ret: bool, text: str, default: int = 0, *,
         para: bool = False, diag: bool = False) -> RegisterInfo:
    return RegisterInfo(rd, wr, ret, para, diag, default, text)


#: the named rows of the interface table; every other address is reserved
REGISTERS: dict[Reg, RegisterInfo] = {
    Reg.REG_SSI_POS: _row(True, False, False, "Actual binary SSI encoder value"),
    Reg.REG_MAGIC_NO: _row(True, False, False, "Magic number (0xaa55cc33)", MAGIC_NO),
    Reg.REG_HW_VER: _row(True, False, False, "Hardware version", HW_VERSION),
    Reg.REG_SW_VER: _row(True, False, False, "Software version", SW_VERSION),
    Reg.REG_SF: _row(True, True, False, "Special Function register"),
    Reg.REG_WR_ADR: _row(True, False, False, "Pointer register OUT"),
    Reg.REG_RD_ADR: _row(True, False, False, "Pointer register IN"),
    Reg.REG_DIAG1: _row(True, False, False, "Diagnostics data", diag=True),
    Reg.REG_PARA1: _row(True, True, True, "Parameter data", PARA1_DEFAULT, para=True),
    Reg.REG_GRAY_POS: _row(True, False, False, "Actual Gray-coded SSI encoder value"),
    Reg.REG_SSI_FRAME: _row(True, False, False, "Complete frame read from SSI encoder"),
    Reg.REG_CMP1: _row(True, True, False, "Comparison value 1"),
    Reg.REG_CMP2: _row(True, True, False, "Comparison value 2"),
    Reg.REG_LOWER_LIMIT: _row(True, True, True, "Lower limit"),
    Reg.REG_UPPER_LIMIT: _row(True, True, True, "Upper limit", VALUE_MAX),
    Reg.REG_OFFSET: _row(True, True, True, "Offset value"),
    Reg.REG_SSI_MASK: _row(True, True, True, "Selection of the SSI encoder diagnostics"),
}

#: retentive registers in address order (000 interface table, "Storage in module")
RETENTIVE: tuple[Reg, ...] = tuple(r for r, i in REGISTERS.items() if i.retentive)
#: the "parameter registers" LD48 leaves alone (000 "Resetting the register bank")
PARAMETER_REGISTERS: tuple[Reg, ...] = tuple(r for r, i in REGISTERS.items() if i.parameter)


def info(addr: int) -> RegisterInfo | None:
    """The interface-table row of ``addr``, or None if the address is reserved/out of range."""
    try:
        return REGISTERS[Reg(addr)]
    except ValueError:
        return None


def describe_refusal(addr: int, write: bool = True) -> str | None:
    """Why a process-data read/write of ``addr`` is refused in any case, or None if allowed.

    Value-dependent refusals (invalid REG_PARA1 set, REG_SF signature, endurance) are decided
    by the module at write time; this only answers from the interface table of 000.
    """
    if not 0 <= addr < REGISTER_COUNT:
        return f"out of range 0..{REGISTER_COUNT - 1}"
    row = info(addr)
    if row is None:
        return "reserved"
    if write and not row.writable:
        return "read-only"
    if not write and not row.readable:
        return "write-only"
    return None
