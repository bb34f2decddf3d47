"""The bus status keeps every finding: what the bus did since the last message is added to a
status that is already WARN for another reason (ROS diagnostics: one status, one message that
says what is wrong), instead of being dropped."""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticStatus

from ssi_bridge.ros.diagnostics import bus_status
from ssi_bridge.ros.node_status import BusFindings


def _findings() -> BusFindings:
    """The findings alone: no master (no foreign-traffic or error-frame findings)."""
    return BusFindings(lambda: None, lambda: 1.0)


def _bus(achieved_rate: float) -> DiagnosticStatus:
    return bus_status("/ssi_bridge: bus", "can", alive=True, connected=True,
                      achieved_rate=achieved_rate, publish_rate=100.0, counters={})


def test_undecodable_frames_are_named_beside_a_low_cycle_rate() -> None:
    status = _findings().applied(_bus(65.0), {"undecodable_frames": 300})
    assert status.level == DiagnosticStatus.WARN
    assert "cycle rate 65.0 Hz below 100.0 Hz" in status.message
    assert "undecodable_frames +300" in status.message


def test_a_finding_replaces_the_ok_message_and_a_quiet_bus_changes_nothing() -> None:
    diags = _findings()
    status = diags.applied(_bus(100.0), {"nmt_restarts": 1})
    assert (status.level, status.message) == (DiagnosticStatus.WARN, "nmt_restarts +1")
    quiet = diags.applied(_bus(100.0), {"nmt_restarts": 1})  # nothing grew since
    assert (quiet.level, quiet.message) == (DiagnosticStatus.OK, "cycling at 100.0 Hz")
