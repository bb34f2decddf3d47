"""The encoder's own status bits through the installed node: PowerFail (003), parity (001
§5.5.7) under bit noise with config/noise_guard.yaml, the TR checksum (001 §5.2.4.2), ERR_PARA from an invalid REG_PARA1 at
the module (000 "Error detection"), each in ~/status, /diagnostics and ~/events."""

from __future__ import annotations

from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.msg import Event, Status
from ssi_bridge_msgs.srv import InjectFault

from .conftest import inject, latest_status

REPO = Path(__file__).resolve().parents[2]
K = InjectFault.Request
PERIOD = 0.5


def _channel(status, joint):
    for _, msg in reversed(status):
        for ch in msg.channels:
            if ch.joint == joint:
                return ch
    return None


def test_power_failure_bit_in_status_diagnostics_and_events(running, probe):
    # 003 "The last data bit can be a PowerFail bit": 24 position bits + PowerFail = 25 clocks;
    # REG_PARA1 drops it from the value (INVALID_BITS_LSB 1) and REG_SSI_MASK 0xC0 copies frame
    # bit 0 (the last bit clocked) into SSI_STS0 and SSI_DIAG (000 Table 3)
    node = running({"joints": ["pf"], "pf.family": "SSI25_POWERFAIL", "pf.para1": 0x19010100,
                    "pf.ssi_mask": 0xC0, "pf.motion.kind": "still", "pf.motion.start": 0.5,
                    "diagnostics_period": PERIOD})
    status = probe.subscribe(Status, node.topic("~/status"))
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    events = probe.subscribe(Event, node.topic("~/events"))
    probe.wait_for(lambda: (ch := _channel(status, "pf")) is not None and ch.frame_checked,
                   10.0, "a checked frame", node)
    ch = _channel(status, "pf")
    assert not ch.power_failure and ch.reg_ssi_pos == 2048  # 0.5 rev of 4096 steps
    res = inject(probe, node, kind=K.POWER_FAILURE)
    assert "no power-fail bit" not in res.message
    probe.wait_for(lambda: _channel(status, "pf").power_failure, 5.0, "power_failure", node)
    ch = _channel(status, "pf")
    assert ch.ssi_sts0 and ch.ssi_diag and ch.ssi_frame & 1 and ch.reg_ssi_pos == 2048
    probe.wait_for(lambda: (st := latest_status(diags, "/ssi_bridge: pf")) is not None
                   and st.level == DiagnosticStatus.ERROR, 2 * PERIOD + 2, "ERROR level", node)
    st = latest_status(diags, "/ssi_bridge: pf")
    assert "POWER_FAILURE" in st.message
    assert {kv.key: kv.value for kv in st.values}["POWER_FAILURE"] == "True"
    probe.wait_for(lambda: any(e.kind == "encoder_status" and "POWER_FAILURE" in e.message
                               for _, e in events), 5.0, "a POWER_FAILURE event", node)
    inject(probe, node, kind=K.CLEAR_ALL)
    probe.wait_for(lambda: not _channel(status, "pf").power_failure, 5.0, "power back", node)
    probe.wait_for(lambda: any("clear again" in e.message for _, e in events), 5.0,
                   "a 'clear again' event", node)


def test_noise_guard_flags_parity_errors_and_holds_the_position(running, probe):
    node = running({"diagnostics_period": PERIOD},
                   params_file=REPO / "config" / "noise_guard.yaml")
    status = probe.subscribe(Status, node.topic("~/status"), qos=500)
    joints = probe.subscribe(JointState, node.topic("joint_states"), qos=500)
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    events = probe.subscribe(Event, node.topic("~/events"))
    probe.wait_for(lambda: (ch := _channel(status, "axis")) is not None and ch.frame_checked,
                   10.0, "a checked frame", node)
    inject(probe, node, kind=K.BIT_NOISE, joint="axis", rate=0.01)
    probe.wait_for(lambda: _channel(status, "axis").frame_errors >= 5, 20.0,
                   "five frames failing the parity check", node)
    inject(probe, node, kind=K.CLEAR_ALL)
    probe.wait_for(lambda: any(e.kind == "encoder_status" and "frame check failed" in e.message
                               for _, e in events), 5.0, "a frame check event", node)
    probe.wait_for(lambda: (st := latest_status(diags, "/ssi_bridge: axis")) is not None
                   and "PARITY_ERROR" in {kv.key for kv in st.values}
                   and int({kv.key: kv.value for kv in st.values}["frame_errors"]) >= 5,
                   2 * PERIOD + 2, "frame_errors in /diagnostics", node)
    # a flagged cycle publishes the previous cycle's position (001 §5.5.7: the frame is
    # not what the encoder sent); match ~/status and joint_states by their stamp
    by_stamp = {(m.header.stamp.sec, m.header.stamp.nanosec): m.position[0] for _, m in joints}
    stamps = sorted(by_stamp)
    held = 0
    for _, msg in status:
        ch = msg.channels[0]
        key = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        if (ch.parity_error or ch.filler_error) and key in by_stamp:
            i = stamps.index(key)
            if i > 0:
                assert by_stamp[key] == by_stamp[stamps[i - 1]]
                held += 1
    assert held > 0, "no flagged cycle with both neighbours seen"


def test_tr_checksum_errors_are_flagged_through_the_node(running, probe):
    # TR "Check sum" format (001 §5.2.4.2): 28 data bits + 15 checksum bits = 43 clocks; the
    # XN-1SSI reads 32 (000 Table 19): the data and 4 checksum bits. REG_PARA1 0x20010820:
    # SSI_FRAME_LEN 32, INVALID_BITS_LSB 8 (4 checksum bits + the 4 trailing zeros of the
    # 16-bit step field), DIS_ERR_SSI (clock 33 carries a checksum bit, not the final 0)
    node = running({"joints": ["ck"], "ck.family": "TR_CHECKSUM", "ck.para1": 0x20010820,
                    "ck.motion.kind": "still", "ck.motion.start": 0.5,
                    "diagnostics_period": PERIOD})
    status = probe.subscribe(Status, node.topic("~/status"), qos=500)
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    events = probe.subscribe(Event, node.topic("~/events"))
    probe.wait_for(lambda: (ch := _channel(status, "ck")) is not None and ch.frame_checked,
                   10.0, "a checked frame", node)
    ch = _channel(status, "ck")
    assert not ch.checksum_error and ch.reg_ssi_pos == 2048  # 0.5 rev of 4096 steps
    inject(probe, node, kind=K.BIT_NOISE, joint="ck", rate=0.01)
    probe.wait_for(lambda: any(m.channels[0].checksum_error for _, m in status), 20.0,
                   "a checksum error in ~/status", node)
    inject(probe, node, kind=K.CLEAR_ALL)
    probe.wait_for(lambda: any(e.kind == "encoder_status" and "frame check failed" in e.message
                               for _, e in events), 5.0, "a frame check event", node)
    probe.wait_for(lambda: (st := latest_status(diags, "/ssi_bridge: ck")) is not None
                   and "CHECKSUM_ERROR" in {kv.key for kv in st.values}
                   and int({kv.key: kv.value for kv in st.values}["frame_errors"]) >= 1,
                   2 * PERIOD + 2, "CHECKSUM_ERROR and frame_errors in /diagnostics", node)


def test_injected_invalid_para1_shows_err_para(running, probe):
    # 000 "Error detection": an invalid parameter set -> ERR_PARA = 1, STS_STOP = 1; the node's
    # own check is bypassed (the set reaches the module's parameter interface directly)
    node = running({"diagnostics_period": PERIOD})
    status = probe.subscribe(Status, node.topic("~/status"))
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    res = inject(probe, node, kind=K.INVALID_PARA1)
    assert "INVALID_PARA1" in res.message
    probe.wait_for(lambda: (ch := _channel(status, "joint1")) is not None and ch.err_para,
                   5.0, "ERR_PARA in ~/status", node)
    assert _channel(status, "joint1").sts_stop
    probe.wait_for(lambda: (st := latest_status(diags, "/ssi_bridge: joint1")) is not None
                   and st.level == DiagnosticStatus.ERROR and "ERR_PARA" in st.message,
                   2 * PERIOD + 2, "ERR_PARA in /diagnostics", node)
    inject(probe, node, kind=K.CLEAR_ALL)
    probe.wait_for(lambda: not _channel(status, "joint1").err_para, 5.0, "ERR_PARA clear", node)
