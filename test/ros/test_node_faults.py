"""Fault injection -> diagnostics levels, and recovery after clearing (docs/node.md table).

Detection follows the manuals: a broken data or clock wire fails the XN-1SSI ZERO test /
start level -> ERR_SSI (000 "Error detection / messages"); an encoder error bit mapped by
REG_SSI_MASK with EN_D0_DS raises SSI_DIAG (000 Table 3); a silent gateway stops its
heartbeat (CiA 301) -> the bus status goes ERROR.
"""

from __future__ import annotations

import math
import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.srv import InjectFault, WriteRegister

from .conftest import inject, latest_status, wait_for_level

PERIOD = 0.5
K = InjectFault.Request


@pytest.mark.parametrize("kind", [K.DATA_WIRE_BREAK, K.CLOCK_WIRE_BREAK])
def test_wire_faults_are_errors_until_cleared(running, probe, kind):
    node = running({"diagnostics_period": PERIOD})
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    wait_for_level(probe, node, diags, "/ssi_bridge: joint1", DiagnosticStatus.OK, 5.0)
    inject(probe, node, kind=kind)
    wait_for_level(probe, node, diags, "/ssi_bridge: joint1", DiagnosticStatus.ERROR, 2 * PERIOD + 1)
    st = latest_status(diags, "/ssi_bridge: joint1")
    assert "ERR_SSI" in st.message, st.message
    inject(probe, node, kind=K.CLEAR_ALL)
    wait_for_level(probe, node, diags, "/ssi_bridge: joint1", DiagnosticStatus.OK, 2 * PERIOD + 1)


def test_power_failure_on_an_encoder_without_the_bit_says_so(running, probe):
    node = running()
    res = inject(probe, node, kind=K.POWER_FAILURE)
    assert "no power-fail bit" in res.message, res.message


def test_fault_with_a_duration_clears_itself(running, probe):
    node = running({"diagnostics_period": PERIOD})
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    joints = probe.subscribe(JointState, node.topic("joint_states"))
    wait_for_level(probe, node, diags, "/ssi_bridge: joint1", DiagnosticStatus.OK, 5.0)
    res = inject(probe, node, kind=K.DATA_WIRE_BREAK, duration=1.0)
    assert "for 1 s" in res.message
    wait_for_level(probe, node, diags, "/ssi_bridge: joint1", DiagnosticStatus.ERROR, 2 * PERIOD + 1)
    wait_for_level(probe, node, diags, "/ssi_bridge: joint1", DiagnosticStatus.OK, 1.0 + 2 * PERIOD + 1)
    probe.wait_for(lambda: len(joints) > 0 and not math.isnan(joints[-1][1].velocity[0]), 2.0,
                   "a measured velocity after recovery", node)
    time.sleep(0.3)
    v = [m.velocity[0] for _, m in joints]
    assert any(math.isnan(x) for x in v), "velocity is NaN (unknown) while ERR_SSI freezes REG_SSI_POS"
    speed = 2 * math.pi * 0.25  # the default simulated shaft
    after = [x for x in v[-20:] if not math.isnan(x)]
    assert after and max(abs(x - speed) for x in after) < 0.1 * speed, \
        "no velocity spike when the frozen position catches up after the fault"


def test_encoder_error_bit_via_reg_ssi_mask_warns(running, probe):
    # AHM36 multiturn: 12 + 14 position bits + error bit = 27-bit frame (004 §3.1); the error
    # bit is frame bit 0, REG_SSI_MASK byte 0 = EN_D0_RMS0 | EN_D0_DS | SEL 0 = 0xC0
    node = running({"joints": ["a"], "a.family": "AHM36_MULTI", "a.para1": 0x1B010100,
                    "diagnostics_period": PERIOD})
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    ok = probe.call(WriteRegister, node.topic("~/write_register"),
                    WriteRegister.Request(address=51, value=0xC0))
    assert ok.success, ok.message
    wait_for_level(probe, node, diags, "/ssi_bridge: a", DiagnosticStatus.OK, 5.0)
    inject(probe, node, kind=K.ENCODER_ERROR)
    # the frame check sees the bit at once; the module's SSI_DIAG follows after the debounce,
    # and the status then names both
    probe.wait_for(lambda: (st := latest_status(diags, "/ssi_bridge: a")) is not None
                   and st.level == DiagnosticStatus.WARN and "SSI_DIAG" in st.message,
                   2 * PERIOD + 1, "WARN naming SSI_DIAG", node)
    inject(probe, node, kind=K.CLEAR_ALL)
    wait_for_level(probe, node, diags, "/ssi_bridge: a", DiagnosticStatus.OK, 2 * PERIOD + 1)


def test_silent_gateway_is_a_bus_error_and_recovers(running, probe):
    node = running({"diagnostics_period": PERIOD})
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    wait_for_level(probe, node, diags, "/ssi_bridge: bus", DiagnosticStatus.OK, 5.0)
    inject(probe, node, kind=K.GATEWAY_SILENT)
    wait_for_level(probe, node, diags, "/ssi_bridge: bus", DiagnosticStatus.ERROR, 2 * PERIOD + 1)
    assert "silent" in latest_status(diags, "/ssi_bridge: bus").message
    wait_for_level(probe, node, diags, "/ssi_bridge: joint1", DiagnosticStatus.STALE, 2 * PERIOD + 1)
    inject(probe, node, kind=K.CLEAR_ALL)
    wait_for_level(probe, node, diags, "/ssi_bridge: bus", DiagnosticStatus.OK, 3 * PERIOD + 2)
    wait_for_level(probe, node, diags, "/ssi_bridge: joint1", DiagnosticStatus.OK, 2 * PERIOD + 1)


def test_total_can_frame_loss_makes_the_joint_stale(running, probe):
    node = running({"diagnostics_period": PERIOD})
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    wait_for_level(probe, node, diags, "/ssi_bridge: joint1", DiagnosticStatus.OK, 5.0)
    inject(probe, node, kind=K.CAN_FRAME_LOSS, rate=1.0)
    wait_for_level(probe, node, diags, "/ssi_bridge: joint1", DiagnosticStatus.STALE, 2 * PERIOD + 1)
    inject(probe, node, kind=K.CLEAR_ALL)
    wait_for_level(probe, node, diags, "/ssi_bridge: joint1", DiagnosticStatus.OK, 3 * PERIOD + 2)


@pytest.mark.parametrize("request_, words", [
    (K(kind=99), "unknown fault kind 99"),
    (K(kind=K.BIT_NOISE, rate=0.0), "needs a rate in (0, 1]"),
    (K(kind=K.DATA_WIRE_BREAK, duration=-1.0), "duration"),
    (K(kind=K.DATA_WIRE_BREAK, joint="nope"), "unknown joint"),
])
def test_bad_fault_requests_are_refused(shared_node, shared_probe, request_, words):
    node = shared_node()  # a refusal injects nothing: one node serves every case
    res = shared_probe.call(InjectFault, node.topic("~/inject_fault"), request_)
    assert not res.success and words in res.message, res.message
