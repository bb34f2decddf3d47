"""One master, several XN-GW-CANOPEN stations on one bus (docs/node.md, Stations).

Two simulated stations (node 1 with two encoders, node 3 with one), each a station child
process on udp_multicast, behind one node: every joint publishes its own motion, and a silent
station (its heartbeat stops, CiA 301) makes only its own joints stale. The same on the
virtual bus, a register write reaching only the joint's station, EMCY per station, one SYNC
per cycle for both stations and the shipped two-station config run in process:
test/core/test_inprocess_stations.py (docs/testing.md).
"""

from __future__ import annotations

import math
import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState

from .conftest import joint_of, latest_status, wait_for_level
from ssi_bridge_msgs.srv import InjectFault
from support.stations import assert_own_motion

PERIOD = 0.5
#: rev/s and start (rev) of each joint's simulated constant motion
MOTION = {"a": (0.05, 1.0), "b": (-0.1, 2.0), "c": (0.2, 3.0)}
STATION = {"a": 1, "b": 1, "c": 3}
SLOT = {"a": 1, "b": 2, "c": 1}
RATE = 100.0
#: one count of the GENERIC encoder (8192 steps/rev) in rad
STEP = 2 * math.pi / 8192


def _params(extra: dict | None = None) -> dict:
    params = {"joints": list(MOTION), "stations": [1, 3], "diagnostics_period": PERIOD,
              "publish_rate": RATE}
    for joint, (velocity, start) in MOTION.items():
        params.update({f"{joint}.station": STATION[joint], f"{joint}.slot": SLOT[joint],
                       f"{joint}.motion.velocity": velocity, f"{joint}.motion.start": start})
    params.update(extra or {})
    return params


@pytest.mark.parametrize("transport", ["udp_multicast"])  # virtual: test/core/test_inprocess_stations.py
def test_three_joints_on_two_stations_publish_their_own_motion(running, probe, transport):
    """udp_multicast: one station child process per station (virtual, both stations in the
    node's process, runs in process: test/core/test_inprocess_stations.py)."""
    t_start = time.monotonic()
    node = running(_params({"simulation.transport": transport}))
    msgs = probe.subscribe(JointState, node.topic("joint_states"))
    probe.wait_for(lambda: len(msgs) > 60, 10.0, "joint_states of both stations", node)
    elapsed = time.monotonic() - t_start
    assert_own_motion([m for _, m in msgs], MOTION, STEP, RATE, elapsed)


@pytest.mark.parametrize("transport", ["udp_multicast"])  # virtual: test/core/test_inprocess_stations.py
def test_a_silent_station_stales_only_its_joints(running, probe, transport):
    node = running(_params({"simulation.transport": transport}))
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    msgs = probe.subscribe(JointState, node.topic("joint_states"))
    for name in ("/ssi_bridge: station 1", "/ssi_bridge: station 3", "/ssi_bridge: a",
                 "/ssi_bridge: c"):
        wait_for_level(probe, node, diags, name, DiagnosticStatus.OK, 5.0)
    res = probe.call(InjectFault, node.topic("~/inject_fault"),
                     InjectFault.Request(kind=InjectFault.Request.GATEWAY_SILENT, joint="c"))
    assert res.success and "station 3" in res.message, res.message
    wait_for_level(probe, node, diags, "/ssi_bridge: station 3", DiagnosticStatus.ERROR,
                2 * PERIOD + 1)
    wait_for_level(probe, node, diags, "/ssi_bridge: c", DiagnosticStatus.STALE, 2 * PERIOD + 1)
    assert "silent" in latest_status(diags, "/ssi_bridge: station 3").message
    n = len(diags)
    probe.wait_for(lambda: len(diags) > n + 2, 5.0, "diagnostics while station 3 is silent",
                   node)
    # station 1 and its joints are OK while station 3 stays silent and c STALE (a loaded
    # machine may hold back a few of station 1's SYNCs too: WARN for a moment, then OK again)
    for name in ("/ssi_bridge: station 1", "/ssi_bridge: a", "/ssi_bridge: b"):
        wait_for_level(probe, node, diags, name, DiagnosticStatus.OK, 2 * PERIOD + 3)
    assert latest_status(diags, "/ssi_bridge: c").level == DiagnosticStatus.STALE
    assert latest_status(diags, "/ssi_bridge: station 3").level == DiagnosticStatus.ERROR
    # station 1's joints keep moving; c has no sample latched at any stamp: left out
    k = len(msgs)
    probe.wait_for(lambda: len(msgs) > k + 30, 5.0, "joint_states during the silence", node)
    window = [m for _, m in msgs[k:]]
    for name in ("a", "b"):
        seen = [joint_of(m, name) for m in window if joint_of(m, name) is not None]
        assert seen and seen[-1][0] != seen[0][0], f"{name} keeps moving"
    assert all(joint_of(m, "c") is None for m in window), "c is left out while silent"
    res = probe.call(InjectFault, node.topic("~/inject_fault"),
                     InjectFault.Request(kind=InjectFault.Request.CLEAR_ALL))
    assert res.success, res.message
    # back: heard again, configured again (NMT, PDOs) and fresh samples; slower when loaded
    for name in ("/ssi_bridge: station 3", "/ssi_bridge: c"):
        wait_for_level(probe, node, diags, name, DiagnosticStatus.OK, 3 * PERIOD + 4)
