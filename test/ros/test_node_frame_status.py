"""The encoder's own status bits through the installed node: the PowerFail bit (003) in
~/status, /diagnostics and ~/events, the ROS wiring of the frame checks.

The checks themselves (parity under bit noise with config/noise_guard.yaml, the TR checksum,
ERR_PARA, the frame checks after a register read) run in process:
test/core/test_inprocess_frame_status.py (docs/testing.md)."""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from ssi_bridge_msgs.msg import Event, Status
from ssi_bridge_msgs.srv import InjectFault

from .conftest import inject, latest_status

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
