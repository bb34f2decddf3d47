"""A params file the node cannot run is refused before anything is started.

A REG_PARA1 the module would refuse with ERR_PARA (000 Table 19: SSI_FRAME_LEN 1..32, a
reserved SSI_BIT_RATE, INVALID_BITS_MSB + INVALID_BITS_LSB < SSI_FRAME_LEN, reserved bits 0),
an encoder family no preset has, and a family/override pair the simulated station cannot build
(001 §5.2.4.2: at most 16 step bits in the check sum format) were refused only after the
station process had started and the gateway was configured: 4-7 log lines came first. Now the
node's whole output is the one refusal line, it exits 1, and the station's retentive bank
(written as soon as a simulated module exists) was never created.
"""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.mark.parametrize("params, words", [
    ({"joint1.para1": 0x21010000}, "joint1.para1 0x21010000 is invalid: SSI_FRAME_LEN = 33"),
    ({"joint1.para1": 0x19080000}, "SSI_BIT_RATE = 8 is reserved"),
    ({"joint1.para1": 0x05000500}, "INVALID_BITS_MSB + INVALID_BITS_LSB = 5"),
    ({"joint1.para1": 0x19010001}, "reserved bits"),
    ({"joint1.family": "AFM60_MULTY"}, "joint1.family 'AFM60_MULTY': unknown encoder family"),
    ({"joints": ["a", "b"], "b.family": "NOPE", "b.para1": 0x21010000}, "b.family 'NOPE'"),
    ({"joint1.family": "TR_CHECKSUM", "joint1.steps_per_rev": 131072},
     "131072 steps do not fit 16 singleturn bits"),
])
def test_a_bad_joint_is_refused_in_one_line_before_any_side_effect(start_node, tmp_path: Path,
                                                                   params, words):
    bank = tmp_path / "bank_refused" / "retentive.json"
    node = start_node({**params, "storage_path": str(bank)})
    assert node.proc.wait(60) == 1, node.log()
    lines = [line for line in node.log().splitlines() if line.strip()]
    assert len(lines) == 1, "more than the refusal:\n" + node.log()
    assert lines[0].startswith("ssi_bridge_node: cannot start: ") and words in lines[0], lines
    assert not bank.parent.exists(), "the simulated station was started"


def test_a_bad_para1_is_refused_on_real_hardware_too(start_node):
    # simulation off: no station to start, but the master would have opened the bus and
    # configured the gateway before refusing; nobody serves this channel
    node = start_node({"simulation.enabled": False, "joint1.para1": 0x21010000})
    assert node.proc.wait(60) == 1, node.log()
    lines = [line for line in node.log().splitlines() if line.strip()]
    assert len(lines) == 1 and "SSI_FRAME_LEN = 33" in lines[0], node.log()
