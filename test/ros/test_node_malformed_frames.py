"""Malformed CANopen frames on the node's bus: counted in the bus diagnostics, no traceback.

Through the installed node and its station child on CAN over UDP multicast (loopback). A third
node sends empty heartbeats of node 1 (CiA 301: 1 byte, the NMT state) and SDO segments to the
station that belong to no transfer. Before: each empty heartbeat raised inside canopen's
``NmtMaster.on_heartbeat`` (``callback_errors`` and an ERROR line), and the station child
logged canopen's traceback ``AttributeError: 'NoneType' object has no attribute 'extend'``
into the node's log. Now the bus status counts ``malformed_frames`` and is WARN while it grows
(as for ``malformed_pdos``), the station child logs one line per second, and both go on.
"""

from __future__ import annotations

import os
import time

import can
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

from ssi_bridge.base.udp_bus import open_udp_bus

from support.stations import gone as _gone
from support.stations import station_of as _station_of

from .conftest import station_channel, latest_status, wait_for_level

PERIOD = 0.5
HEARTBEATS, SEGMENTS = 20, 20


def _values(st) -> dict[str, str]:
    return {kv.key: kv.value for kv in st.values}


def test_malformed_frames_are_counted_in_the_bus_diagnostics(running, probe, domain_id):
    name = f"malformed_{domain_id}_{os.getpid()}"
    node = running({"bus.channel": name, "diagnostics_period": PERIOD})
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    wait_for_level(probe, node, diags, "/ssi_bridge: joint1", DiagnosticStatus.OK, 20.0)
    station = _station_of(node)
    other = open_udp_bus(station_channel(name, domain_id))  # another node on the bus
    try:
        for _ in range(HEARTBEATS):
            other.send(can.Message(arbitration_id=0x701, data=b"", is_extended_id=False))
            other.send(can.Message(arbitration_id=0x601, data=bytes(8), is_extended_id=False))
            time.sleep(0.002)
    finally:
        other.shutdown()
    probe.wait_for(lambda: (st := latest_status(diags, "/ssi_bridge: bus")) is not None
                   and int(_values(st).get("malformed_frames", 0)) == HEARTBEATS,
                   2 * PERIOD + 5, f"malformed_frames {HEARTBEATS} in the bus status", node)
    warned = [st.message for _t, m in diags for st in m.status
              if st.name == "/ssi_bridge: bus" and st.level == DiagnosticStatus.WARN]
    assert any("malformed_frames +" in w for w in warned), warned
    bus = _values(latest_status(diags, "/ssi_bridge: bus"))
    assert int(bus["callback_errors"]) == 0, bus
    assert node.proc.poll() is None and not _gone(station)
    wait_for_level(probe, node, diags, "/ssi_bridge: bus", DiagnosticStatus.OK, 2 * PERIOD + 5)
    probe.wait_for(lambda: "SDO segment outside a transfer" in node.log(), 5.0,
                   "the station child's line in the node's log", node)
    log = node.log()
    assert "Traceback" not in log and "has no attribute" not in log, log[-3000:]
    assert "[ERROR]" not in log, log[-3000:]
    assert 1 <= log.count("is no heartbeat of node 1") <= 10, log[-3000:]
