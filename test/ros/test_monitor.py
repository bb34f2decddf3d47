"""The monitor command: what a newcomer sees of a running bridge in the terminal.

Its report is built from the node's own joint_states and /diagnostics (docs/node.md: one
status per joint named ``<node FQN>: <joint>``, one ``<node FQN>: bus``), so the levels it
prints are the ones the diagnostics carry, e.g. ERROR for a broken SSI data wire (000 "Error
detection / messages": ERR_SSI).
"""

from __future__ import annotations

import signal
import subprocess
import threading
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.srv import InjectFault

from ssi_bridge.tools.monitor import (
    DISCOVERY_S, MonitorState, build_parser, joint_states_topic,
)

from .conftest import installed_executable

REPO = Path(__file__).resolve().parents[2]


def _status(name: str, level: bytes, message: str, hw: str, **values: str) -> DiagnosticStatus:
    return DiagnosticStatus(name=name, level=level, message=message, hardware_id=hw,
                            values=[KeyValue(key=k, value=v) for k, v in values.items()])


def test_report_shows_joints_levels_and_the_bus_load_of_this_bridge():
    state = MonitorState()
    state.on_joint_states(JointState(name=["lift", "tilt"], position=[1.5, -0.25],
                                     velocity=[0.5, float("nan")]))
    state.on_diagnostics(DiagnosticArray(status=[
        _status("/ssi_bridge: lift", DiagnosticStatus.OK, "reading",
                "virtual:a node 1 slot 1 XN-1SSI"),
        _status("/ssi_bridge: tilt", DiagnosticStatus.ERROR, "ERR_SSI: wire break",
                "virtual:a node 1 slot 2 XN-1SSI"),
        _status("/ssi_bridge: bus", DiagnosticStatus.OK, "cycling at 100.0 Hz",
                "virtual:a node 1 XN-GW-CANOPEN", bus_load_percent="12.5", sdo_aborts="0"),
    ]))
    lines = state.report("/ssi_bridge", "/joint_states", elapsed=1.0)
    text = "\n".join(lines)
    assert "/joint_states 1.0 msg/s" in lines[0]
    lift = next(line for line in lines if line.strip().startswith("lift"))
    assert "1.5000" in lift and "0.5000" in lift and "OK" in lift
    tilt = next(line for line in lines if line.strip().startswith("tilt"))
    assert "-0.2500" in tilt and "nan" in tilt and "ERROR ERR_SSI" in tilt
    assert "bus: OK cycling at 100.0 Hz; bus_load_percent 12.5" in text
    assert "sdo_aborts" not in text, "only the load keys of the bus status are shown"
    assert state.received == 0, "the rate counts messages since the last report"


def test_report_ignores_the_bus_status_of_another_bridge_and_says_what_it_waits_for():
    state = MonitorState()
    assert "node /x/ssi_bridge not found" in state.report("/x/ssi_bridge", "/x/joint_states",
                                                          1.0, node_seen=False)[0]
    state.on_joint_states(JointState(name=["lift"], position=[0.0], velocity=[0.0]))
    state.on_diagnostics(DiagnosticArray(status=[
        _status("/ssi_bridge: lift", DiagnosticStatus.OK, "reading",
                "virtual:a node 1 slot 1 XN-1SSI"),
        _status("/ssi_bridge: bus", DiagnosticStatus.ERROR, "gateway silent",
                "virtual:b node 1 XN-GW-CANOPEN")]))
    assert "bus: (no diagnostics yet)" in "\n".join(
        state.report("/ssi_bridge", "/joint_states", 1.0))


def test_first_seconds_wait_for_discovery_and_the_columns_carry_units():
    state = MonitorState()
    early = state.report("/ssi_bridge", "/joint_states", 1.0, node_seen=False, waited=1.2)[0]
    assert "waiting for discovery, 1 of 5 s" in early and "not found" not in early, early
    late = state.report("/ssi_bridge", "/joint_states", 1.0, node_seen=False,
                        waited=DISCOVERY_S + 1.0)[0]
    assert "node /ssi_bridge not found after 6 s" in late and "discovery" not in late, late
    assert DISCOVERY_S == 5.0 and "first 5 s" in build_parser().format_help()
    state.on_joint_states(JointState(name=["lift"], position=[1.5], velocity=[0.5]))
    lines = state.report("/ssi_bridge", "/joint_states", 1.0)
    assert lines[2].split() == ["rad", "(m)", "rad/s", "(m/s)"], lines[:3]
    assert "msg/s" in lines[0]


def test_help_is_plain_text():
    text = build_parser().format_help()
    assert "--namespace" in text and "Ctrl-C" in text
    for markup in ("``", ":py:", "::", ".. "):
        assert markup not in text, f"reStructuredText markup {markup!r} in --help"
    assert joint_states_topic("/station_a/") == "/station_a/joint_states"
    assert joint_states_topic("") == "/joint_states"


def test_monitor_prints_the_running_bridge_and_stops_cleanly_on_ctrl_c(start_node, probe):
    node = start_node({"joints": ["lift", "tilt"], "diagnostics_period": 0.5},
                      namespace="/station_a")
    seen = probe.subscribe(JointState, node.topic("joint_states"))
    probe.wait_for(lambda: len(seen) > 0, 30.0, "the first joint_states message", node)
    res = probe.call(InjectFault, node.topic("~/inject_fault"),
                     InjectFault.Request(joint="tilt", kind=InjectFault.Request.DATA_WIRE_BREAK))
    assert res.success, res.message

    mon = subprocess.Popen([str(installed_executable("monitor")), "--namespace", "station_a"], env=node.env,
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                           start_new_session=True)
    out: list[str] = []
    reader = threading.Thread(target=lambda: out.extend(mon.stdout), daemon=True)
    reader.start()
    try:
        def reported() -> bool:
            text = "".join(out)
            return ("ERROR ERR_SSI" in text and any(
                line.strip().startswith("lift") and " OK " in line for line in out)
                and "bus: " in text and "cycling at" in text)
        probe.wait_for(reported, 30.0, f"a monitor report with both joints:\n{''.join(out)}", node)
    finally:
        mon.send_signal(signal.SIGINT)
        try:
            code = mon.wait(10.0)
        except subprocess.TimeoutExpired:
            mon.kill()
            code = mon.wait(5.0)
    reader.join(5.0)
    text = "".join(out)
    assert code == 0, f"monitor exited {code} on Ctrl-C:\n{text}"
    assert "Traceback" not in text, text
    assert "/station_a/ssi_bridge: /station_a/joint_states" in text
    tilt = [line for line in out if line.strip().startswith("tilt")]
    assert tilt and "ERROR" in tilt[-1], tilt
