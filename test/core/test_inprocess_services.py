"""The register services' work (core/bridge.py, what ~/set_preset, ~/reset_registers,
~/set_control and ~/read_register / ~/write_register call) against the simulated station in
process, and the raw frame and status bits each cycle's ~/status carries.

Register semantics from 000 chapter 1: REG_OFFSET (50) is subtracted from the encoder value
("Offset function"), REG_SF (4) with "LD48" 0x6C643438 restores the retentive registers but
REG_PARA1 ("Resetting the register bank"). Moved from test/ros/test_node_services.py
(docs/testing.md); the node keeps the services' wording of each refusal, the diagnostics
rate during reads, the recorder's refusal and the service queue under bursts.
"""

from __future__ import annotations

import math

import pytest

from ssi_bridge.exceptions import ConfigError

REG_CMP1, REG_OFFSET, REG_LOWER_LIMIT = 34, 50, 48
STEP = 2 * math.pi / 8192  # one count of the default 8192-step joint (rad)


def _published(b, joint: str) -> list[float]:
    return [p.output.position for r in list(b.results) for p in r.published
            if p.joint.name == joint]


def test_set_preset_moves_the_zero_point(inprocess):
    b = inprocess({"joints": ["j"], "j.motion.kind": "still", "j.motion.start": 1.25})
    j = b.bridge.joint("")
    offset, position, _text = b.bridge.set_preset(j, 0.5)
    # encoder value 1.25 rev * 8192 = 10240 counts; target 0.5 rad -> 651.9 -> 652 counts
    assert offset == 10240 - round(0.5 / STEP)
    assert position == pytest.approx(0.5, abs=STEP)
    assert b.bridge.read_register(j, REG_OFFSET) == offset
    count = len(_published(b, "j"))
    b.run_until(lambda: len(_published(b, "j")) > count + 2, 5.0, "joint_states after the preset")
    assert _published(b, "j")[-1] == pytest.approx(0.5, abs=STEP)

    _offset, negative, _text = b.bridge.set_preset(j, -3.0)
    assert negative == pytest.approx(-3.0, abs=STEP), \
        "REG_SSI_POS below zero must read as a negative Integer32 position (object 0x6820)"


@pytest.mark.parametrize("position, words", [
    (float("nan"), "not a finite number"),
    (float("inf"), "not a finite number"),
    (1e12, "Integer32"),
])
def test_set_preset_refuses_bad_positions(inprocess, position, words):
    b = inprocess()
    j = b.bridge.joint("")
    with pytest.raises(ConfigError) as refused:
        b.bridge.set_preset(j, position)
    assert words in str(refused.value), refused.value
    assert b.bridge.read_register(j, REG_OFFSET) == 0  # a refusal changes nothing


def test_reset_registers_ld48_keeps_para1_ld20_restores_it(inprocess):
    b = inprocess({"joint1.para1": 0x19020000})  # 250 kbit/s, not the factory 500 kbit/s
    j = b.bridge.joint("")
    b.bridge.write_register(j, REG_LOWER_LIMIT, 77)
    b.bridge.reset_registers(j, include_parameters=False)
    assert b.bridge.read_register(j, REG_LOWER_LIMIT) == 0, "LD48 restores REG_LOWER_LIMIT's default"
    assert b.bridge.read_register(j, 20) == 0x19020000, "LD48 keeps REG_PARA1"
    b.bridge.reset_registers(j, include_parameters=True)
    assert b.bridge.read_register(j, 20) == 0x19010000, "LD20 restores REG_PARA1's default 0x19010000"


def test_set_control_stop_and_comparator(inprocess):
    b = inprocess({"joints": ["j"], "j.motion.kind": "still", "j.motion.start": 0.5})
    j = b.bridge.joint("")
    # REG_SSI_POS = 0.5 rev * 8192 = 4096: put CMP1 there so it matches (000 comparator table)
    b.bridge.write_register(j, REG_CMP1, 4096)
    b.bridge.set_control(j, enable_cmp1=True)
    b.run_until(lambda: (ch := b.channel("j")) is not None and ch.sts_cmp1, 5.0,
                "STS_CMP1 = 1 with REG_SSI_POS = REG_CMP1")
    ch = b.channel("j")
    assert ch.flag_cmp1 and ch.rel_cmp1 and ch.reg_ssi_pos == 4096

    b.bridge.set_control(j, stop=True)
    b.run_until(lambda: b.channel("j").sts_stop, 5.0, "STS_STOP = 1")
    assert not b.channel("j").sts_cmp1, "EN_CMP1 = 0 zeroes STS/REL/FLAG_CMP1"


def test_status_carries_the_raw_frame_and_every_bit(inprocess):
    b = inprocess({"joints": ["j"], "j.motion.kind": "still", "j.motion.start": 0.5})
    b.run_until(lambda: (ch := b.channel("j")) is not None and ch.ssi_frame_valid, 5.0,
                "a status with REG_SSI_FRAME")
    ch = b.channel("j")
    # GENERIC 25-bit binary frame: REG_SSI_FRAME = the position itself (000 register 33)
    assert ch.ssi_frame == 4096 and ch.reg_ssi_pos == 4096
    assert ch.reg_rd_adr == 33 and not ch.reg_rd_abort
    assert len(ch.process_input) == 8 and ch.process_input[4] == 33
    assert not (ch.err_ssi or ch.err_para or ch.sts_stop)
