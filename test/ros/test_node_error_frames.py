"""CAN error frames in the bus diagnostics: bus-off ERROR, error passive WARN, a count per class.

The simulated wire delivers the error frames a master's controller reports (faults BUS_OFF
and ERROR_PASSIVE of ``~/inject_fault``, linux/can/error.h layout), from the station child
over udp_multicast as any frame. Before: error frames were only counted in ``can_errors``,
bus-off and error passive not told apart, the bus OK.
"""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from ssi_bridge_msgs.srv import InjectFault

from .conftest import inject, latest_status

PERIOD = 0.5
BUS = "/ssi_bridge: bus"
K = InjectFault.Request


def _values(st) -> dict[str, str]:
    return {kv.key: kv.value for kv in st.values}


def _bus(diags, level, words: str):
    def ok() -> bool:
        st = latest_status(diags, BUS)
        return st is not None and st.level == level and words in st.message
    return ok


def test_bus_off_is_an_error_and_error_passive_a_warning(running, probe):
    node = running({"diagnostics_period": PERIOD, "simulation.transport": "udp_multicast"})
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    probe.wait_for(_bus(diags, DiagnosticStatus.OK, ""), 20.0, "bus OK", node)

    inject(probe, node, kind=K.ERROR_PASSIVE)
    probe.wait_for(_bus(diags, DiagnosticStatus.WARN, "error passive"), 2 * PERIOD + 3,
                   "bus WARN naming error passive", node)
    values = _values(latest_status(diags, BUS))
    assert values["can_controller_state"] == "error passive", values
    assert int(values["error_frames_controller"]) == 2, values
    assert int(values["error_frames_error_counters"]) == 2, values
    assert values["can_tx_error_counter"] == "128", values
    inject(probe, node, kind=K.CLEAR_ALL)
    probe.wait_for(_bus(diags, DiagnosticStatus.OK, ""), 2 * PERIOD + 3,
                   "bus OK once the controller is error active again", node)

    inject(probe, node, kind=K.BUS_OFF)
    probe.wait_for(_bus(diags, DiagnosticStatus.ERROR, "bus-off"), 2 * PERIOD + 3,
                   "bus ERROR naming bus-off", node)
    assert _values(latest_status(diags, BUS))["error_frames_bus_off"] == "1"
    refused = probe.call(InjectFault, node.topic("~/inject_fault"), K(kind=K.ENCODER_ERROR))
    assert not refused.success and "BUS_OFF" in refused.message, refused.message
    inject(probe, node, kind=K.CLEAR_ALL)
    probe.wait_for(_bus(diags, DiagnosticStatus.OK, ""), 3 * PERIOD + 3,
                   "bus OK after the restart", node)
    values = _values(latest_status(diags, BUS))
    assert values["can_controller_state"] == "error active", values
    assert values["error_frames_restarted"] == "1", values
    log = node.log()
    assert log.count("CAN error frame (bus_off") == 1, log[-3000:]
    assert "Traceback" not in log
    assert node.proc.poll() is None
