"""Process input / output images bit for bit (000 chapter 2, PROFIBUS-DP data image)."""

from __future__ import annotations

import pytest

from ssi_bridge.protocol.images import (
    CmpControl, CmpStatus, ModuleStatus, ProcessInput, ProcessOutput,
)


def assert_image(got: bytes, expected: bytes, what: str) -> None:
    assert got == expected, f"{what}: got {got.hex(' ')}, expected {expected.hex(' ')}"


# 000 "Process input" table: (field change, byte index, byte value)
@pytest.mark.parametrize("fields, index, value", [
    ({"reg_rd_abort": True}, 4, 0x80), ({"reg_rd_adr": 63}, 4, 0x3F), ({"reg_rd_adr": 20}, 4, 0x14),
    ({"reg_wr_accept": True}, 5, 0x80), ({"reg_wr_akn": True}, 5, 0x40),
    ({"ssi_sts": 0b1000}, 5, 0x08), ({"ssi_sts": 0b0001}, 5, 0x01),
    ({"cmp": CmpStatus.STS_UP}, 6, 0x80), ({"cmp": CmpStatus.STS_DN}, 6, 0x40),
    ({"cmp": CmpStatus.REL_CMP2}, 6, 0x20), ({"cmp": CmpStatus.FLAG_CMP2}, 6, 0x10),
    ({"cmp": CmpStatus.STS_CMP2}, 6, 0x08), ({"cmp": CmpStatus.REL_CMP1}, 6, 0x04),
    ({"cmp": CmpStatus.FLAG_CMP1}, 6, 0x02), ({"cmp": CmpStatus.STS_CMP1}, 6, 0x01),
    ({"sts": ModuleStatus.STS_STOP}, 7, 0x80), ({"sts": ModuleStatus.ERR_PARA}, 7, 0x10),
    ({"sts": ModuleStatus.STS_UFLW}, 7, 0x08), ({"sts": ModuleStatus.STS_OFLW}, 7, 0x04),
    ({"sts": ModuleStatus.ERR_SSI}, 7, 0x02), ({"sts": ModuleStatus.SSI_DIAG}, 7, 0x01),
])
def test_process_input_bit_positions(fields: dict, index: int, value: int) -> None:
    expected = bytearray(8)
    expected[index] = value
    image = ProcessInput(**fields).encode()
    assert_image(image, bytes(expected), f"000 process input {fields}")
    assert ProcessInput.decode(image) == ProcessInput(**fields), "decode inverts encode"


# 000 "Process output" table
@pytest.mark.parametrize("fields, index, value", [
    ({"reg_rd_adr": 33}, 4, 0x21), ({"reg_wr": True}, 5, 0x80), ({"reg_wr_adr": 51}, 5, 0x33),
    ({"cmp": CmpControl.CLR_CMP2}, 6, 0x10), ({"cmp": CmpControl.EN_CMP2}, 6, 0x08),
    ({"cmp": CmpControl.CLR_CMP1}, 6, 0x02), ({"cmp": CmpControl.EN_CMP1}, 6, 0x01),
    ({"stop": True}, 7, 0x80),
])
def test_process_output_bit_positions(fields: dict, index: int, value: int) -> None:
    expected = bytearray(8)
    expected[index] = value
    image = ProcessOutput(**fields).encode()
    assert_image(image, bytes(expected), f"000 process output {fields}")
    assert ProcessOutput.decode(image) == ProcessOutput(**fields)


def test_data_bytes_are_big_endian() -> None:
    # 000 process input/output: "Byte 0 = REG_RD_DATA, Byte 3 ... Byte 3 = REG_RD_DATA, Byte 0"
    assert_image(ProcessInput(reg_rd_data=0x11223344).encode()[:4], b"\x11\x22\x33\x44", "RD_DATA")
    assert ProcessOutput.decode(b"\xAA\x55\xCC\x33\0\0\0\0").reg_wr_data == 0xAA55CC33


def test_reserved_output_bits_are_ignored() -> None:
    # 000 process output: X = reserved (byte 4 bits 7,6; byte 5 bit 6; byte 6 bits 7,6,5,2; byte 7 bits 6..0)
    out = ProcessOutput.decode(bytes([0, 0, 0, 0, 0xC0, 0x40, 0xE4, 0x7F]))
    assert out == ProcessOutput(), f"reserved bits must not act: {out}"


@pytest.mark.parametrize("length", [0, 7, 9, 16])
def test_wrong_length_is_a_value_error(length: int) -> None:
    with pytest.raises(ValueError, match="8 bytes"):
        ProcessOutput.decode(bytes(length))
    with pytest.raises(ValueError, match="8 bytes"):
        ProcessInput.decode(bytes(length))


def test_bits_names_every_input_bit() -> None:
    bits = ProcessInput(sts=ModuleStatus.ERR_SSI, ssi_sts=0b0100).bits()
    assert bits["ERR_SSI"] == 1 and bits["SSI_STS2"] == 1 and bits["STS_STOP"] == 0
    assert {"REG_RD_ABORT", "REG_WR_AKN", "REG_WR_ACCEPT", "STS_UP", "FLAG_CMP2"} <= bits.keys()
