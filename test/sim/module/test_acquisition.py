"""Acquisition per cycle (000 chapter 1 "Transmission procedure", "Offset function",
Table 19, process input STS_STOP / ERR_SSI / ERR_PARA)."""

from __future__ import annotations

import pytest

from ssi_bridge.sim.module.acquisition import bin_to_gray, gray_to_bin
from ssi_bridge.protocol.diagnostics import Diag
from ssi_bridge.protocol.images import ModuleStatus
from ssi_bridge.protocol.registers import Para1, Reg
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi


def para(**fields: object) -> int:
    return Para1(**fields).encode()  # type: ignore[arg-type]


def test_default_module_reads_a_25_bit_binary_frame(reader, module) -> None:
    # 000 register table: REG_PARA1 default 0x19010000 = 25 bits, 500 kBit/s, binary
    reader.push(0x1ABCDEF)
    module.cycle(0.5)
    assert reader.calls == [(0.5, 25, 500_000.0)], "one frame of SSI_FRAME_LEN bits at SSI_BIT_RATE"
    assert module.ssi_pos == 0x1ABCDEF
    assert module.read_register(Reg.REG_SSI_FRAME) == 0x1ABCDEF
    assert module.read_register(Reg.REG_GRAY_POS) == bin_to_gray(0x1ABCDEF)
    assert module.latch_time == 0.5 and module.last_readout is not None
    assert module.diag == Diag(0)


def test_default_construction_without_reader() -> None:
    m = Xn1Ssi()
    m.cycle(0.0)
    assert m.ssi_pos == 0 and m.last_readout is None and m.latch_time is None
    assert m.process_input() == bytes(8)


@pytest.mark.parametrize("value", [0, 1, 2, 3, 0x155, 0xFFFF, 0x1FFFFFF, 0x123456])
def test_gray_frames_are_decoded(reader, module, value: int) -> None:
    # 000 Table 19 SSI_CODE_G/D = 1: "SSI encoder sends data in Gray code"; REG_GRAY_POS (32)
    module.write_para1(para(ssi_frame_len=25, ssi_code_gray=True))
    reader.push(bin_to_gray(value))
    module.cycle(0.0)
    assert module.ssi_pos == value, f"Gray 0x{bin_to_gray(value):X} -> {value}"
    assert module.read_register(Reg.REG_GRAY_POS) == bin_to_gray(value)
    assert gray_to_bin(bin_to_gray(value)) == value


@pytest.mark.parametrize("frame_len, msb, lsb, frame, expected", [
    (25, 0, 0, 0x1FFFFFF, 0x1FFFFFF),
    (25, 1, 0, 0x1FFFFFF, 0x0FFFFFF),        # MSB-side bit masked to 0
    (25, 0, 1, 0x1FFFFFE, 0x0FFFFFF),        # LSB-side bit shifted out
    (13, 0, 2, 0b1010101010111, 0b10101010101),
    (32, 7, 15, 0xFFFFFFFF, (1 << 10) - 1),  # meaningful width 32 - 7 - 15 = 10
    (16, 3, 4, 0xF0F0, 0x10F),          # 0xF0F masked to 16 - 3 - 4 = 9 bits
])
def test_invalid_bits(reader, module, frame_len, msb, lsb, frame, expected) -> None:
    # 000 "Transmission procedure": MSB side masked, LSB side shifted right; Table 19 widths
    module.write_para1(para(ssi_frame_len=frame_len, invalid_bits_msb=msb, invalid_bits_lsb=lsb))
    reader.push(frame)
    module.cycle(0.0)
    assert module.ssi_pos == expected, f"frame 0x{frame:X} len {frame_len} msb {msb} lsb {lsb}"
    assert module.read_register(Reg.REG_SSI_FRAME) == frame & ((1 << frame_len) - 1)


def test_gray_with_invalid_bits_decodes_only_the_position_field(reader, module) -> None:
    # 000 "Transmission procedure": invalid bits removed; decoding only the field keeps a set
    # MSB status bit from corrupting the Gray decode (docs/module.md "Order of processing")
    module.write_para1(para(ssi_frame_len=16, invalid_bits_msb=1, invalid_bits_lsb=2, ssi_code_gray=True))
    position = 1000
    frame = (1 << 15) | (bin_to_gray(position) << 2) | 0b11
    reader.push(frame)
    module.cycle(0.0)
    assert module.ssi_pos == position


@pytest.mark.parametrize("dis_err_ssi, trailer, err_ssi", [
    (False, 0, False), (False, 1, True), (True, 1, False), (True, 0, False)])
def test_zero_test_of_the_data_line(reader, module, dis_err_ssi, trailer, err_ssi) -> None:
    # 000 Table 19 DIS_ERR_SSI; process input ERR_SSI "SSI encoder signal faulty (cable break)"
    module.write_para1(para(dis_err_ssi=dis_err_ssi))
    reader.push(5, trailer_bit=trailer)
    module.cycle(0.0)
    assert bool(module.status.sts & ModuleStatus.ERR_SSI) == err_ssi
    assert (Diag.ERR_SSI in module.diag) == err_ssi, "diagnostics bit 1 wire-break"


@pytest.mark.parametrize("dis_err_ssi, err_ssi", [(False, True), (True, False)])
def test_missing_start_level_is_an_ssi_error(reader, module, dis_err_ssi, err_ssi) -> None:
    # data wire break: the line reads LOW where the idle "pause 1" is expected -> ERR_SSI
    # (docs/module.md "SSI error check"); DIS_ERR_SSI switches the whole check off
    module.write_para1(para(dis_err_ssi=dis_err_ssi))
    reader.push(0, start_bit=0)
    module.cycle(0.0)
    assert (Diag.ERR_SSI in module.diag) == err_ssi


def test_wire_break_keeps_the_last_good_position(reader, module) -> None:
    # 000 ERR_SSI: the faulty frame is not taken as a position (docs/module.md)
    reader.push(100).push(0x1FFFFFF, trailer_bit=1).push(101)
    module.cycle(0.0)
    module.cycle(0.001)
    assert module.ssi_pos == 100 and Diag.ERR_SSI in module.diag
    module.cycle(0.002)
    assert module.ssi_pos == 101 and Diag.ERR_SSI not in module.diag, "ERR_SSI is non-retentive"


def test_stop_freezes_acquisition(reader, master, module) -> None:
    # 000 process output STOP = 1 "interrupt communication"; process input STS_STOP = 1
    reader.push(10).push(20).push(30)
    assert master.cycle().sts == ModuleStatus(0)
    image = master.cycle(stop=True)
    assert image.sts & ModuleStatus.STS_STOP and module.ssi_pos == 10
    assert len(reader.calls) == 1, "no clock burst while stopped"
    assert not master.cycle(stop=False).sts & ModuleStatus.STS_STOP
    assert module.ssi_pos == 20


def test_invalid_parameter_set_stops_communication(reader, module) -> None:
    # 000 process input ERR_PARA / STS_STOP "stopped as STOP = 1 or ERR_PARA = 1"
    with pytest.raises(Exception):
        module.write_para1(0x19080000)  # reserved bit rate
    module.cycle(0.0)
    sts = module.status.sts
    assert ModuleStatus.ERR_PARA in sts and ModuleStatus.STS_STOP in sts, str(sts)
    assert reader.calls == [], "no acquisition with ERR_PARA = 1"
    assert Diag.ERR_PARA in module.diag, "diagnostics bit 4 parameter error"
    assert module.read_register(Reg.REG_PARA1) == 0x19010000, "rejected set not taken"
    module.write_para1(0x19010000)
    module.cycle(0.001)
    assert module.status.sts == ModuleStatus(0) and len(reader.calls) == 1


@pytest.mark.parametrize("encoder, offset, pos", [
    (1000, 0, 1000), (1000, 10, 990), (5, 10, 0xFFFFFFFB), (0, 1, 0xFFFFFFFF)])
def test_offset_is_subtracted(reader, module, encoder, offset, pos) -> None:
    # 000 "Offset function": (REG_SSI_POS) = SSI encoder - (REG_OFFSET); 0 switches it off
    module.write_register(Reg.REG_OFFSET, offset)
    reader.push(encoder)
    module.cycle(0.0)
    assert module.ssi_pos == pos, f"{encoder} - {offset}"
    assert module.read_register(Reg.REG_SSI_POS) == pos


@pytest.mark.parametrize("code, hz", [(0, 1e6), (3, 125e3), (4, 100e3), (7, 62.5e3)])
def test_bit_rate_reaches_the_reader(reader, module, code, hz) -> None:
    # 000 Table 19 SSI_BIT_RATE codes
    module.write_para1(para(ssi_bit_rate=code))
    module.cycle(0.0)
    assert reader.calls[-1][2] == hz
