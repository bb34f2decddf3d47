"""Fault injection -> the joint's and the bus's diagnostics, and recovery after clearing
(docs/node.md table), in process: the master and the simulated station on a virtual bus.

Detection follows the manuals: a broken data or clock wire fails the XN-1SSI ZERO test /
start level -> ERR_SSI (000 "Error detection / messages"); an encoder error bit mapped by
REG_SSI_MASK with EN_D0_DS raises SSI_DIAG (000 Table 3); a silent gateway stops its
heartbeat (CiA 301) -> the bus status goes ERROR. Moved from test/ros/test_node_faults.py
(docs/testing.md): the same faults, levels, words and time bounds, without a node process;
test_node_station_process.py keeps the one test that ~/inject_fault reaches a station child.
"""

from __future__ import annotations

import math

import pytest
from diagnostic_msgs.msg import DiagnosticStatus as D

from ssi_bridge.exceptions import ConfigError
from ssi_bridge.sim.gateway.simulation import FaultKind as K

#: the node tests' diagnostics_period: a level shows within two periods and a second
PERIOD = 0.5


def _at(b, joint: str, level: bytes, timeout: float) -> None:
    try:
        b.run_until(lambda: b.level(joint) == level, timeout, f"{joint} at level {level!r}")
    except AssertionError as err:
        raise AssertionError(f"{err}; the status says: {b.status(joint).message}") from None


def _inject(b, kind: K, joint: str = "", rate: float = 0.0, duration: float = 0.0) -> str:
    return b.bridge.inject_fault(b.bridge.joint(joint), int(kind), rate, duration)


@pytest.mark.parametrize("kind", [K.DATA_WIRE_BREAK, K.CLOCK_WIRE_BREAK])
def test_wire_faults_are_errors_until_cleared(inprocess, kind):
    b = inprocess()
    _at(b, "joint1", D.OK, 5.0)
    _inject(b, kind)
    _at(b, "joint1", D.ERROR, 2 * PERIOD + 1)
    assert "ERR_SSI" in b.status("joint1").message, b.status("joint1").message
    _inject(b, K.CLEAR_ALL)
    _at(b, "joint1", D.OK, 2 * PERIOD + 1)


def test_power_failure_on_an_encoder_without_the_bit_says_so(inprocess):
    b = inprocess()
    assert "no power-fail bit" in _inject(b, K.POWER_FAILURE)


def _velocities(b) -> list[float]:
    return [part.output.velocity for r in b.results for part in r.published
            if part.joint.name == "joint1"]


def test_fault_with_a_duration_clears_itself(inprocess):
    b = inprocess()
    _at(b, "joint1", D.OK, 5.0)
    assert "for 1 s" in _inject(b, K.DATA_WIRE_BREAK, duration=1.0)
    _at(b, "joint1", D.ERROR, 2 * PERIOD + 1)
    _at(b, "joint1", D.OK, 1.0 + 2 * PERIOD + 1)
    b.run_until(lambda: (v := _velocities(b)) and not math.isnan(v[-1]), 2.0,
                "a measured velocity after recovery")
    b.run_for(0.3)
    v = _velocities(b)
    assert any(math.isnan(x) for x in v), "velocity is NaN (unknown) while ERR_SSI freezes REG_SSI_POS"
    speed = 2 * math.pi * 0.25  # the default simulated shaft
    after = [x for x in v[-20:] if not math.isnan(x)]
    assert after and max(abs(x - speed) for x in after) < 0.1 * speed, \
        "no velocity spike when the frozen position catches up after the fault"


def test_encoder_error_bit_via_reg_ssi_mask_warns(inprocess):
    # AHM36 multiturn: 12 + 14 position bits + error bit = 27-bit frame (004 §3.1); the error
    # bit is frame bit 0, REG_SSI_MASK byte 0 = EN_D0_RMS0 | EN_D0_DS | SEL 0 = 0xC0
    b = inprocess({"joints": ["a"], "a.family": "AHM36_MULTI", "a.para1": 0x1B010100})
    b.bridge.write_register(b.bridge.joint(""), 51, 0xC0)  # ~/write_register address 51
    _at(b, "a", D.OK, 5.0)
    _inject(b, K.ENCODER_ERROR)
    # the frame check sees the bit at once; the module's SSI_DIAG follows after the debounce,
    # and the status then names both
    b.run_until(lambda: (st := b.status("a")).level == D.WARN and "SSI_DIAG" in st.message,
                2 * PERIOD + 1, "WARN naming SSI_DIAG")
    _inject(b, K.CLEAR_ALL)
    _at(b, "a", D.OK, 2 * PERIOD + 1)


def test_silent_gateway_is_a_bus_error_and_recovers(inprocess):
    b = inprocess()
    b.run_until(lambda: b.bus_status().level == D.OK, 5.0, "bus OK")
    _inject(b, K.GATEWAY_SILENT)
    b.run_until(lambda: b.bus_status().level == D.ERROR, 2 * PERIOD + 1, "bus ERROR")
    assert "silent" in b.bus_status().message
    _at(b, "joint1", D.STALE, 2 * PERIOD + 1)
    _inject(b, K.CLEAR_ALL)
    b.run_until(lambda: b.bus_status().level == D.OK, 3 * PERIOD + 2, "bus OK again")
    _at(b, "joint1", D.OK, 2 * PERIOD + 1)


def test_total_can_frame_loss_makes_the_joint_stale(inprocess):
    b = inprocess()
    _at(b, "joint1", D.OK, 5.0)
    _inject(b, K.CAN_FRAME_LOSS, rate=1.0)
    _at(b, "joint1", D.STALE, 2 * PERIOD + 1)
    _inject(b, K.CLEAR_ALL)
    _at(b, "joint1", D.OK, 3 * PERIOD + 2)


@pytest.mark.parametrize("kind, joint, rate, duration, words", [
    (99, "", 0.0, 0.0, "unknown fault kind 99"),
    (K.BIT_NOISE, "", 0.0, 0.0, "needs a rate in (0, 1]"),
    (K.DATA_WIRE_BREAK, "", 0.0, -1.0, "duration"),
    (K.DATA_WIRE_BREAK, "nope", 0.0, 0.0, "unknown joint"),
])
def test_bad_fault_requests_are_refused(inprocess, kind, joint, rate, duration, words):
    b = inprocess()
    with pytest.raises(ConfigError) as refused:
        b.bridge.inject_fault(b.bridge.joint(joint), int(kind), rate, duration)
    assert words in str(refused.value), refused.value
    assert not b.faults.active  # a refusal injects nothing
