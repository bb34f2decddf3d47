"""Bus faults in the bus status, in process: CAN error frames (bus-off ERROR, error passive
WARN, a count per class) and malformed CANopen frames (counted, WARN while they grow, no
traceback), with the bus status built as the node builds it (support/inprocess_bus.py: the
node's counters, its error beside the bus state and ``BusFindings``) every diagnostics period.

The simulated wire delivers the error frames a master's controller reports (faults BUS_OFF
and ERROR_PASSIVE, linux/can/error.h layout). A third node sends empty heartbeats of node 1
(CiA 301: 1 byte, the NMT state) and SDO segments to the station that belong to no transfer:
the master counts ``malformed_frames``, the station logs one line per second, both go on.
Moved from test/ros/test_node_error_frames.py and test/ros/test_node_malformed_frames.py
(docs/testing.md).
"""

from __future__ import annotations

import logging
import time

import can
import pytest
from diagnostic_msgs.msg import DiagnosticStatus as D

from ssi_bridge.exceptions import ConfigError
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import open_bus
from ssi_bridge.sim.gateway.simulation import FaultKind as K
from support.inprocess_bus import BusDiagnostics

PERIOD = 0.5
HEARTBEATS = 20


@pytest.fixture
def diagnosed(inprocess):
    """An in-process bridge and its bus status every PERIOD."""
    b = inprocess()
    diags = BusDiagnostics(b, PERIOD)
    try:
        yield b, diags
    finally:
        diags.stop()


def _bus(diags, level: bytes, words: str):
    def ok() -> bool:
        st = diags.latest()
        return st is not None and st.level == level and words in st.message
    return ok


def _inject(b, kind: K) -> str:
    return b.bridge.inject_fault(b.bridge.joint(""), int(kind), 0.0, 0.0)


def test_bus_off_is_an_error_and_error_passive_a_warning(diagnosed, caplog):
    caplog.set_level(logging.INFO, logger="ssi_bridge")
    b, diags = diagnosed
    b.run_until(_bus(diags, D.OK, ""), 20.0, "bus OK")

    _inject(b, K.ERROR_PASSIVE)
    b.run_until(_bus(diags, D.WARN, "error passive"), 2 * PERIOD + 3,
                "bus WARN naming error passive")
    values = diags.values()
    assert values["can_controller_state"] == "error passive", values
    assert int(values["error_frames_controller"]) == 2, values
    assert int(values["error_frames_error_counters"]) == 2, values
    assert values["can_tx_error_counter"] == "128", values
    _inject(b, K.CLEAR_ALL)
    b.run_until(_bus(diags, D.OK, ""), 2 * PERIOD + 3,
                "bus OK once the controller is error active again")

    _inject(b, K.BUS_OFF)
    b.run_until(_bus(diags, D.ERROR, "bus-off"), 2 * PERIOD + 3, "bus ERROR naming bus-off")
    assert diags.values()["error_frames_bus_off"] == "1"
    with pytest.raises(ConfigError) as refused:
        _inject(b, K.ENCODER_ERROR)
    assert "BUS_OFF" in str(refused.value), refused.value
    _inject(b, K.CLEAR_ALL)
    b.run_until(_bus(diags, D.OK, ""), 3 * PERIOD + 3, "bus OK after the restart")
    values = diags.values()
    assert values["can_controller_state"] == "error active", values
    assert values["error_frames_restarted"] == "1", values
    lines = [r.getMessage() for r in caplog.records]
    assert sum("CAN error frame (bus_off" in m for m in lines) == 1, lines[-20:]
    assert not [r for r in caplog.records if r.exc_info], "no traceback"


def test_malformed_frames_are_counted_in_the_bus_diagnostics(diagnosed, caplog):
    caplog.set_level(logging.INFO, logger="ssi_bridge")
    b, diags = diagnosed
    b.run_until(lambda: b.level("joint1") == D.OK, 20.0, "joint1 OK")
    other = open_bus(BusConfig(interface="virtual", channel=b.bus.channel))  # another node
    try:
        for _ in range(HEARTBEATS):
            other.send(can.Message(arbitration_id=0x701, data=b"", is_extended_id=False))
            other.send(can.Message(arbitration_id=0x601, data=bytes(8), is_extended_id=False))
            time.sleep(0.002)
    finally:
        other.shutdown()
    b.run_until(lambda: int(diags.values().get("malformed_frames", 0)) == HEARTBEATS,
                2 * PERIOD + 5, f"malformed_frames {HEARTBEATS} in the bus status")
    warned = [st.message for _t, st in list(diags.history) if st.level == D.WARN]
    assert any("malformed_frames +" in w for w in warned), warned
    assert int(diags.values()["callback_errors"]) == 0, diags.values()
    b.run_until(_bus(diags, D.OK, ""), 2 * PERIOD + 5, "bus OK again")
    b.run_until(lambda: any("SDO segment outside a transfer" in r.getMessage()
                            for r in caplog.records), 5.0, "the station's line")
    records = list(caplog.records)
    assert not [r for r in records if r.exc_info], "no traceback"
    assert not [r for r in records if "has no attribute" in r.getMessage()]
    assert not [r for r in records if r.levelno >= logging.ERROR], \
        [r.getMessage() for r in records if r.levelno >= logging.ERROR]
    heartbeat_lines = sum("is no heartbeat of node 1" in r.getMessage() for r in records)
    assert 1 <= heartbeat_lines <= 10, heartbeat_lines
