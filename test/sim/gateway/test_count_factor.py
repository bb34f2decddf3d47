"""REG_SSI_POS counts per encoder step (gateway.station.count_factor) against the module's own
decode (000 Table 19: SSI_FRAME_LEN, INVALID_BITS_LSB), Tannenbaum step fields included."""

from __future__ import annotations

import pytest

from ssi_bridge.sim.encoder.encoder import make_encoder
from ssi_bridge.sim.encoder.motion import Still
from ssi_bridge.protocol.joint_encoder import count_factor
from ssi_bridge.sim.line.line import LineConfig, SsiLine
from ssi_bridge.protocol.registers import Reg
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi


@pytest.mark.parametrize("family, overrides, para1", [
    ("GENERIC", {}, 0x19010000),
    ("TR_PARITY", {}, 0x1A010200),
    # TR check sum (001 §5.2.4.2): 4096 steps in the 16-bit step field end in 4 zeros; 32
    # of 43 clocks, the last 4 read are checksum bits (INVALID_BITS_LSB 4 or 8)
    ("TR_CHECKSUM", {}, 0x20010420),
    ("TR_CHECKSUM", {}, 0x20010820),
    # AHM36 Tannenbaum (004 §3.4): 8192 steps in the 14-bit singleturn field
    ("AHM36_MULTI", {"steps_per_rev": 8192}, 0x1B010100),
])
def test_count_factor_matches_reg_ssi_pos(family: str, overrides: dict, para1: int) -> None:
    value = 3 * 4096 + 1234
    enc = make_encoder(family, Still(0.0), **overrides)
    enc.apply_preset(0.0, value)
    module = Xn1Ssi(SsiLine(enc, LineConfig(check_cable_table=False)))
    module.write_para1(para1)
    module.cycle(0.0)
    assert module.read_register(Reg.REG_SSI_POS) == value * count_factor(enc.config, para1)
