"""The module on the real line and encoder stages (000 chapter 1 acquisition, ERR_SSI on a
wire break; 000 Table 19 DIS_ERR_SSI)."""

from __future__ import annotations

import pytest

from ssi_bridge.protocol.codes import Code
from ssi_bridge.sim.encoder.encoder import make_encoder
from ssi_bridge.sim.encoder.motion import ConstantVelocity, Still
from ssi_bridge.sim.line.line import LineConfig, SsiLine
from ssi_bridge.protocol.diagnostics import Diag
from ssi_bridge.protocol.images import CmpStatus
from ssi_bridge.protocol.registers import Para1, Reg
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi


def on_line(motion=None, **encoder) -> tuple[Xn1Ssi, SsiLine]:
    line = SsiLine(make_encoder("GENERIC", motion or Still(1.25), **encoder),
                   LineConfig(cable_length_m=5.0))
    return Xn1Ssi(line), line


def test_default_parameters_read_the_generic_25_bit_encoder() -> None:
    # 000 REG_PARA1 default: 25-bit binary at 500 kBit/s; 1.25 rev x 8192 steps = 10240
    module, line = on_line()
    module.cycle(0.0)
    assert module.ssi_pos == 10240 and module.diag == Diag(0)
    assert module.last_readout is not None and module.last_readout.n_bits == 25


def test_gray_encoder_with_gray_parameter() -> None:
    # 000 Table 19 SSI_CODE_G/D = 1
    module, _ = on_line(code=Code.GRAY)
    module.write_para1(Para1(ssi_code_gray=True).encode())
    module.cycle(0.0)
    assert module.ssi_pos == 10240


def test_moving_shaft_sets_sts_up() -> None:
    # 000 process input STS_UP: the encoder values are incremented
    module, _ = on_line(ConstantVelocity(10.0))
    module.cycle(0.0)
    module.cycle(0.01)
    assert CmpStatus.STS_UP in module.status.cmp and module.ssi_pos > 0


@pytest.mark.parametrize("fault", ["data_break", "clock_break"])
def test_wire_breaks_raise_err_ssi(fault: str) -> None:
    # 000 ERR_SSI "SSI encoder signal faulty (e.g. due to a cable break)"
    module, line = on_line()
    module.cycle(0.0)
    setattr(line.faults, fault, True)
    module.cycle(0.001)
    assert Diag.ERR_SSI in module.diag, f"{fault} must be detected"
    assert module.read_register(Reg.REG_SSI_POS) == 10240, "last good position kept"
    line.faults.clear()
    module.cycle(0.002)
    assert Diag.ERR_SSI not in module.diag


def test_dis_err_ssi_disables_the_check() -> None:
    # 000 Table 19 DIS_ERR_SSI = 1: no ZERO test (DeviceNet 124: "disable SSI error detection")
    module, line = on_line()
    module.write_para1(Para1(dis_err_ssi=True).encode())
    line.faults.clock_break = True
    module.cycle(0.0)
    assert Diag.ERR_SSI not in module.diag
