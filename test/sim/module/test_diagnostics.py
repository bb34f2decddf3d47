"""Diagnostics byte and CANopen emergency values (000 chapter 2 "Diagnostics", Table 27,
chapter 4 "Additional emergencies")."""

from __future__ import annotations

import pytest

from ssi_bridge.exceptions import ParameterError
from ssi_bridge.protocol.diagnostics import Diag, DiagTracker, diag_edges
from ssi_bridge.protocol.images import ModuleStatus
from ssi_bridge.protocol.registers import Reg


@pytest.mark.parametrize("bit, position, emcy", [
    (Diag.SSI_DIAG, 0, 0x01), (Diag.ERR_SSI, 1, 0x02), (Diag.STS_OFLW, 2, 0x04),
    (Diag.STS_UFLW, 3, 0x08), (Diag.ERR_PARA, 4, 0x10)])
def test_bit_positions_and_emcy_values(bit: Diag, position: int, emcy: int) -> None:
    # 000 "Diagnostics" Bit 0..4; "Additional emergencies" byte 5 = 0x01 .. 0x10
    assert int(bit) == 1 << position
    (edge,) = diag_edges(Diag(0), bit, slot=3)
    assert (edge.emcy_value, edge.rising, edge.slot) == (emcy, True, 3)


def test_diag_bits_equal_the_low_bits_of_process_input_byte_7() -> None:
    # Table 27 (object 5804) and process input byte 7 share bit positions 0..4
    for bit in Diag:
        assert int(bit) == int(ModuleStatus[bit.name]), bit.name


def test_tracker_reports_rising_and_falling_edges() -> None:
    tracker = DiagTracker(slot=1)
    assert tracker.update(Diag(0)) == []
    up = tracker.update(Diag.ERR_SSI | Diag.STS_OFLW)
    assert [(e.emcy_value, e.rising) for e in up] == [(0x02, True), (0x04, True)]
    assert tracker.update(Diag.ERR_SSI | Diag.STS_OFLW) == [], "no edge while unchanged"
    down = tracker.update(Diag.STS_OFLW)
    assert [(e.emcy_value, e.rising, e.text) for e in down] == [(0x02, False, "Wire-break")]


def test_module_diag_follows_the_conditions(reader, module, master) -> None:
    # wire break -> bit 1, limit -> bit 2, parameter error -> bit 4; REG_DIAG1 reads the byte
    tracker = DiagTracker()
    reader.push(10, trailer_bit=1).push(10).push(10)
    master.cycle()
    assert [e.emcy_value for e in tracker.update(module.diag)] == [0x02]
    module.write_register(Reg.REG_UPPER_LIMIT, 5)
    master.cycle()
    edges = tracker.update(module.diag)
    assert [(e.emcy_value, e.rising) for e in edges] == [(0x02, False), (0x04, True)]
    assert module.read_register(Reg.REG_DIAG1) == 0x04
    with pytest.raises(ParameterError):
        module.write_para1(0x00000000)
    assert Diag.ERR_PARA in module.diag, "ERR_PARA shows at once"
    assert master.read(Reg.REG_DIAG1).reg_rd_data == 0x14
