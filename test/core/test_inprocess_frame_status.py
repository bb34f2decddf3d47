"""The encoder's own status bits, in process: PowerFail (003), parity (001 §5.5.7) under bit
noise with config/noise_guard.yaml, the TR checksum (001 §5.2.4.2), ERR_PARA from an invalid
REG_PARA1 at the module (000 "Error detection"), each in the joint's ~/status channel, its
diagnostic status and its ~/events (built by the node's own functions from the cycle core's
results: test/support/inprocess.py). And after a register read the frames are still checked:
the bridge keeps REG_RD_ADR = REG_SSI_FRAME (33) while no handshake runs, so REG_RD_DATA
carries the raw SSI frame every cycle (docs/node.md; 000 "Internal registers").

Moved from test/ros/test_node_frame_status.py and test/ros/test_node_idle_read.py
(docs/testing.md): the same joints, faults and values, without a node process.
"""

from __future__ import annotations

from pathlib import Path

from diagnostic_msgs.msg import DiagnosticStatus as D

from ssi_bridge.protocol.settings import load_params_file
from ssi_bridge.sim.gateway.simulation import FaultKind as K
from support.inprocess import values_of

REPO = Path(__file__).resolve().parents[2]
PERIOD = 0.5
IDLE = 33  # REG_SSI_FRAME
#: 003 PowerFail encoder: 24 position bits + PowerFail = 25 clocks; REG_PARA1 drops it from
#: the value (INVALID_BITS_LSB 1) and REG_SSI_MASK 0xC0 copies frame bit 0 (the last bit
#: clocked) into SSI_STS0 and SSI_DIAG (000 Table 3)
POWERFAIL_JOINT = {"joints": ["pf"], "pf.family": "SSI25_POWERFAIL", "pf.para1": 0x19010100,
                   "pf.ssi_mask": 0xC0, "pf.motion.kind": "still", "pf.motion.start": 0.5}


def _inject(b, kind: K, joint: str = "", rate: float = 0.0) -> str:
    return b.bridge.inject_fault(b.bridge.joint(joint), int(kind), rate, 0.0)


def _checked(b, joint: str) -> bool:
    ch = b.channel(joint)
    return ch is not None and ch.frame_checked


def _idle_and_checked(b, joint: str) -> bool:
    ch = b.channel(joint)
    return ch is not None and ch.reg_rd_adr == IDLE and ch.frame_checked


def _event(b, words: str) -> bool:
    return any(words in text for _joint, _ok, text in b.events())


def test_power_failure_bit_in_status_diagnostics_and_events(inprocess):
    b = inprocess(POWERFAIL_JOINT)
    b.run_until(lambda: _checked(b, "pf"), 10.0, "a checked frame")
    ch = b.channel("pf")
    assert not ch.power_failure and ch.reg_ssi_pos == 2048  # 0.5 rev of 4096 steps
    assert "no power-fail bit" not in _inject(b, K.POWER_FAILURE)
    b.run_until(lambda: b.channel("pf").power_failure, 5.0, "power_failure")
    ch = b.channel("pf")
    assert ch.ssi_sts0 and ch.ssi_diag and ch.ssi_frame & 1 and ch.reg_ssi_pos == 2048
    b.run_until(lambda: b.level("pf") == D.ERROR, 2 * PERIOD + 2, "ERROR level")
    st = b.status("pf")
    assert "POWER_FAILURE" in st.message
    assert values_of(st)["POWER_FAILURE"] == "True"
    b.run_until(lambda: _event(b, "POWER_FAILURE"), 5.0, "a POWER_FAILURE event")
    _inject(b, K.CLEAR_ALL)
    b.run_until(lambda: not b.channel("pf").power_failure, 5.0, "power back")
    b.run_until(lambda: _event(b, "clear again"), 5.0, "a 'clear again' event")


def test_noise_guard_flags_parity_errors_and_holds_the_position(inprocess):
    with open(REPO / "config" / "noise_guard.yaml") as f:
        b = inprocess(load_params_file(f))
    b.run_until(lambda: _checked(b, "axis"), 10.0, "a checked frame")
    _inject(b, K.BIT_NOISE, "axis", rate=0.01)
    b.run_until(lambda: b.channel("axis").frame_errors >= 5, 20.0,
                "five frames failing the parity check")
    _inject(b, K.CLEAR_ALL)
    b.run_until(lambda: _event(b, "frame check failed"), 5.0, "a frame check event")
    st = b.status("axis")
    assert "PARITY_ERROR" in values_of(st) and int(values_of(st)["frame_errors"]) >= 5
    # a flagged cycle publishes the previous cycle's position (001 §5.5.7: the frame is not
    # what the encoder sent): each cycle's ~/status channel beside its published position
    held, previous = 0, None
    for result, msg in zip(b.results, b.status_msgs):
        published = {p.joint.name: p.output.position for p in result.published}
        position = published.get("axis")
        ch = {c.joint: c for c in msg.channels}.get("axis")
        if (ch is not None and (ch.parity_error or ch.filler_error) and position is not None
                and previous is not None):
            assert position == previous
            held += 1
        previous = position  # None: the cycle before was left out, not a neighbour seen
    assert held > 0, "no flagged cycle with both neighbours seen"


def test_tr_checksum_errors_are_flagged(inprocess):
    # TR "Check sum" format (001 §5.2.4.2): 28 data bits + 15 checksum bits = 43 clocks; the
    # XN-1SSI reads 32 (000 Table 19): the data and 4 checksum bits. REG_PARA1 0x20010820:
    # SSI_FRAME_LEN 32, INVALID_BITS_LSB 8 (4 checksum bits + the 4 trailing zeros of the
    # 16-bit step field), DIS_ERR_SSI (clock 33 carries a checksum bit, not the final 0)
    b = inprocess({"joints": ["ck"], "ck.family": "TR_CHECKSUM", "ck.para1": 0x20010820,
                   "ck.motion.kind": "still", "ck.motion.start": 0.5})
    b.run_until(lambda: _checked(b, "ck"), 10.0, "a checked frame")
    ch = b.channel("ck")
    assert not ch.checksum_error and ch.reg_ssi_pos == 2048  # 0.5 rev of 4096 steps
    _inject(b, K.BIT_NOISE, "ck", rate=0.01)
    b.run_until(lambda: any(c.checksum_error for c in b.channels("ck")), 20.0,
                "a checksum error in ~/status")
    _inject(b, K.CLEAR_ALL)
    b.run_until(lambda: _event(b, "frame check failed"), 5.0, "a frame check event")
    st = b.status("ck")
    assert "CHECKSUM_ERROR" in values_of(st) and int(values_of(st)["frame_errors"]) >= 1


def test_injected_invalid_para1_shows_err_para(inprocess):
    # 000 "Error detection": an invalid parameter set -> ERR_PARA = 1, STS_STOP = 1; the
    # bridge's own check is bypassed (the set reaches the module's parameter interface directly)
    b = inprocess()
    assert "INVALID_PARA1" in _inject(b, K.INVALID_PARA1)
    b.run_until(lambda: (ch := b.channel("joint1")) is not None and ch.err_para, 5.0,
                "ERR_PARA in ~/status")
    assert b.channel("joint1").sts_stop
    b.run_until(lambda: (st := b.status("joint1")).level == D.ERROR and "ERR_PARA" in st.message,
                2 * PERIOD + 2, "ERR_PARA in the diagnostics")
    _inject(b, K.CLEAR_ALL)
    b.run_until(lambda: not b.channel("joint1").err_para, 5.0, "ERR_PARA clear")


def test_after_read_register_a_power_failure_is_an_error(inprocess):
    """A register read of REG_PARA1, then POWER_FAILURE: ERROR with POWER_FAILURE True, as
    without the read (003 PowerFail bit; 000 Table 3 SSI_STS0/SSI_DIAG)."""
    b = inprocess(POWERFAIL_JOINT)
    b.run_until(lambda: _idle_and_checked(b, "pf"), 10.0, "a checked frame")
    assert b.bridge.read_register(b.bridge.joint("pf"), 20) == 0x19010100
    b.run_until(lambda: _idle_and_checked(b, "pf"), 2.0,
                "REG_RD_ADR back at 33 and the frame checked after the read")
    _inject(b, K.POWER_FAILURE)
    b.run_until(lambda: b.level("pf") == D.ERROR, 2 * PERIOD + 2, "ERROR level")
    st = b.status("pf")
    assert "POWER_FAILURE" in st.message, st.message
    assert values_of(st)["POWER_FAILURE"] == "True"
    assert b.channel("pf").power_failure


def test_the_encoder_error_injection_leaves_the_frame_checks_on(inprocess):
    """ENCODER_ERROR reads REG_SSI_MASK through the handshake; afterwards REG_RD_ADR is 33
    again and the frames are checked (AHM36 error bit, 004 §3.1)."""
    b = inprocess({"joints": ["a"], "a.family": "AHM36_MULTI", "a.para1": 0x1B010100,
                   "a.ssi_mask": 0xC0})
    b.run_until(lambda: _idle_and_checked(b, "a"), 10.0, "a checked frame")
    _inject(b, K.ENCODER_ERROR)
    count = len(b.results)
    b.run_until(lambda: len(b.results) > count + 10 and _idle_and_checked(b, "a"), 3.0,
                "REG_RD_ADR back at 33 and the frame checked after the injection")
