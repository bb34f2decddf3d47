"""After a register read the node still checks the joint's frames.

The node keeps REG_RD_ADR = REG_SSI_FRAME (33) while no handshake runs, so REG_RD_DATA carries
the raw SSI frame every cycle and the frame checks (PowerFail, parity, filler, check sum,
encoder error bit) run on it (docs/node.md; 000 "Internal registers": REG_RD_DATA shows the
register REG_RD_ADR names). Before, ``~/read_register`` and the ENCODER_ERROR injection (which
reads REG_SSI_MASK) left REG_RD_ADR at the register they read: a power failure afterwards was
only WARN "SSI_DIAG" with ``POWER_FAILURE`` false, until the node restarted. Installed node,
simulated station, as test_node_frame_status.py.
"""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from ssi_bridge_msgs.msg import Status
from ssi_bridge_msgs.srv import InjectFault, ReadRegister

from .conftest import inject, latest_status

K = InjectFault.Request
PERIOD = 0.5
IDLE = 33  # REG_SSI_FRAME
#: 003 PowerFail encoder: 24 position bits + PowerFail = 25 clocks, REG_SSI_MASK 0xC0 copies
#: frame bit 0 into SSI_STS0 and SSI_DIAG (000 Table 3); as test_node_frame_status.py
POWERFAIL_JOINT = {"joints": ["pf"], "pf.family": "SSI25_POWERFAIL", "pf.para1": 0x19010100,
                   "pf.ssi_mask": 0xC0, "pf.motion.kind": "still", "pf.motion.start": 0.5,
                   "diagnostics_period": PERIOD}


def _channel(status, joint):
    for _, msg in reversed(status):
        for ch in msg.channels:
            if ch.joint == joint:
                return ch
    return None


def _idle_and_checked(status, joint) -> bool:
    ch = _channel(status, joint)
    return ch is not None and ch.reg_rd_adr == IDLE and ch.frame_checked


def test_after_read_register_a_power_failure_is_an_error(running, probe):
    """~/read_register REG_PARA1, then POWER_FAILURE: diagnostics ERROR with POWER_FAILURE
    True, as without the read (003 PowerFail bit; 000 Table 3 SSI_STS0/SSI_DIAG)."""
    node = running(POWERFAIL_JOINT)
    status = probe.subscribe(Status, node.topic("~/status"))
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    probe.wait_for(lambda: _idle_and_checked(status, "pf"), 10.0, "a checked frame", node)
    res = probe.call(ReadRegister, node.topic("~/read_register"),
                     ReadRegister.Request(joint="pf", address=20))
    assert res.success and res.value == 0x19010100, res.message
    probe.wait_for(lambda: _idle_and_checked(status, "pf"), 2.0,
                   "REG_RD_ADR back at 33 and the frame checked after the read", node)
    inject(probe, node, kind=K.POWER_FAILURE)
    probe.wait_for(lambda: (st := latest_status(diags, "/ssi_bridge: pf")) is not None
                   and st.level == DiagnosticStatus.ERROR, 2 * PERIOD + 2, "ERROR level", node)
    st = latest_status(diags, "/ssi_bridge: pf")
    assert "POWER_FAILURE" in st.message, st.message
    assert {kv.key: kv.value for kv in st.values}["POWER_FAILURE"] == "True"
    assert _channel(status, "pf").power_failure


def test_the_encoder_error_injection_leaves_the_frame_checks_on(running, probe):
    """~/inject_fault ENCODER_ERROR reads REG_SSI_MASK through the handshake; afterwards
    REG_RD_ADR is 33 again and the frames are checked (AHM36 error bit, 004 §3.1)."""
    node = running({"joints": ["a"], "a.family": "AHM36_MULTI", "a.para1": 0x1B010100,
                    "a.ssi_mask": 0xC0, "diagnostics_period": PERIOD})
    status = probe.subscribe(Status, node.topic("~/status"))
    probe.wait_for(lambda: _idle_and_checked(status, "a"), 10.0, "a checked frame", node)
    res = inject(probe, node, kind=K.ENCODER_ERROR)
    assert res.success, res.message
    count = len(status)
    probe.wait_for(lambda: len(status) > count + 10 and _idle_and_checked(status, "a"), 3.0,
                   "REG_RD_ADR back at 33 and the frame checked after the injection", node)
