"""Register handshake over the process images (000 chapter 1 "Internal registers - read and
write operations", chapter 2 REG_WR / REG_WR_AKN / REG_WR_ACCEPT / REG_RD_ABORT, Table 9)."""

from __future__ import annotations

import pytest

from ssi_bridge.protocol.registers import SF_LD20, Reg


def test_write_step_by_step(master, module) -> None:
    # 000: REG_WR = 1 -> REG_WR_AKN = 1 with REG_WR_ACCEPT; REG_WR = 0 clears REG_WR_AKN
    idle = master.cycle()
    assert not idle.reg_wr_akn and not idle.reg_wr_accept
    ack = master.cycle(reg_wr=True, reg_wr_adr=Reg.REG_CMP1, reg_wr_data=1234)
    assert ack.reg_wr_akn and ack.reg_wr_accept, f"accepted write: {ack}"
    assert module.read_register(Reg.REG_CMP1) == 1234
    again = master.cycle(reg_wr_data=999)  # REG_WR still 1: ignored (Table 9 REG_WR_AKN)
    assert again.reg_wr_akn and module.read_register(Reg.REG_CMP1) == 1234, "second write ignored"
    done = master.cycle(reg_wr=False)
    assert not done.reg_wr_akn and not done.reg_wr_accept


@pytest.mark.parametrize("addr, value", [
    (Reg.REG_SSI_POS, 1), (Reg.REG_MAGIC_NO, 0), (Reg.REG_DIAG1, 0), (Reg.REG_GRAY_POS, 0),
    (7, 1), (40, 1), (63, 1),                   # reserved
    (Reg.REG_PARA1, 0x19080000),                # invalid parameter set
    (Reg.REG_SF, 0x12345678),                   # not LD20/LD48
])
def test_refused_writes_answer_accept_0(master, module, addr, value) -> None:
    # 000: "If the register could not be written ... REG_WR_ACCEPT = 0"
    ack = master.write(addr, value)
    assert ack.reg_wr_akn and not ack.reg_wr_accept, f"write 0x{value:X} to {addr}: {ack}"


def test_invalid_para_write_via_process_data_keeps_module_running(master, module) -> None:
    # 000 register table: REG_PARA1 WR; an invalid set is refused, the running set stays
    master.write(Reg.REG_PARA1, 0x00010000)
    assert module.read_register(Reg.REG_PARA1) == 0x19010000
    assert not module.status.sts, "refused register write does not raise ERR_PARA"


def test_write_to_retentive_register_and_reset(master, module) -> None:
    assert master.write(Reg.REG_OFFSET, 77).reg_wr_accept
    assert module.read_register(Reg.REG_OFFSET) == 77
    assert master.write(Reg.REG_SF, SF_LD20).reg_wr_accept
    assert module.read_register(Reg.REG_OFFSET) == 0


@pytest.mark.parametrize("addr, expected", [
    (Reg.REG_MAGIC_NO, 0xAA55CC33), (Reg.REG_PARA1, 0x19010000), (Reg.REG_UPPER_LIMIT, 0xFFFFFFFF)])
def test_read_returns_data_and_echo(master, addr, expected) -> None:
    # 000: content in REG_RD_DATA, REG_RD_ADR echoed, REG_RD_ABORT = 0
    image = master.read(addr)
    assert (image.reg_rd_data, image.reg_rd_adr, image.reg_rd_abort) == (expected, addr, False)


@pytest.mark.parametrize("addr", [5, 13, 17, 31, 47, 52, 63])
def test_read_of_reserved_aborts_with_zero_data(master, addr) -> None:
    # 000: "REG_RD_ABORT = 1 ... REG_RD_ADR contains the address ... user data set to ZERO"
    master.read(Reg.REG_MAGIC_NO)
    image = master.read(addr)
    assert image.reg_rd_abort and image.reg_rd_data == 0 and image.reg_rd_adr == addr, str(image)


def test_read_follows_the_live_position(reader, master) -> None:
    # REG_RD_ADR = 0 (REG_SSI_POS) is read every cycle
    reader.push(5).push(6)
    assert master.read(Reg.REG_SSI_POS).reg_rd_data == 5
    assert master.cycle().reg_rd_data == 6


def test_pointer_registers_read_the_output_addresses(master) -> None:
    # 000 register table: REG_WR_ADR (14) "Pointer register OUT", REG_RD_ADR (15) "Pointer register IN"
    image = master.cycle(reg_wr_adr=34, reg_rd_adr=Reg.REG_WR_ADR)
    assert image.reg_rd_data == 34
    assert master.cycle(reg_rd_adr=Reg.REG_RD_ADR).reg_rd_data == Reg.REG_RD_ADR
