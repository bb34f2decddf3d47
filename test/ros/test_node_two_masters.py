"""One master per bus: a second bridge given a bus another master drives does not start.

Two nodes with ``simulation.enabled: false`` on one udp_multicast channel with one separately
started ``station``: the first masters it; the second hears the first's SYNC (and SDO requests to
node 1) before it sends anything, exits 1 with one line naming them and their COB-IDs, and
the first goes on undisturbed. The same for two simulated nodes given the same udp_multicast
channel on purpose: the second starts no station of its own. Before: the second reset and
configured the station under the first (NMT pre-operational, PDO mapping) and ran beside it,
each seeing the other's SYNC only as a WARN.
"""

from __future__ import annotations

import math
import os
import signal
import time

from sensor_msgs.msg import JointState

from ssi_bridge.base.udp_bus import derive_channel

from support.stations import children as _children
from support.stations import ready as _ready
from support.stations import start_station as _start_station


def _one_line_exit_1(node) -> str:
    assert node.proc.wait(60) == 1, node.log()[-3000:]
    lines = [ln for ln in node.log().splitlines() if ln.strip()]
    assert len(lines) == 1, node.log()[-3000:]
    return lines[0]


def _keeps_publishing(probe, node, joints) -> None:
    before = len(joints)
    probe.wait_for(lambda: len(joints) > before + 50, 10.0, "joint_states of the first", node)
    assert all(math.isfinite(m.position[0]) for _t, m in joints[-20:])
    assert node.proc.poll() is None
    assert "not sent by this master" not in node.log(), node.log()[-3000:]


def test_a_second_real_master_on_the_bus_exits_1_naming_the_first(
        tmp_path, domain_id, probe, start_node):
    channel = derive_channel(f"two_masters_{domain_id}_{os.getpid()}")
    bus = {"bus.interface": "udp_multicast", "bus.channel": channel}
    station = _start_station(tmp_path, {"joints": ["joint1"], **bus,
                                        "storage_path": str(tmp_path / "st" / "bank.json")})
    try:
        _ready(station)
        first = start_node({"simulation.enabled": False, **bus})
        joints = probe.subscribe(JointState, first.topic("joint_states"))
        probe.wait_for(lambda: len(joints) > 20, 30.0, "joint_states of the first", first)
        second = start_node({"simulation.enabled": False, **bus}, namespace="/second")
        line = _one_line_exit_1(second)
        assert "cannot start" in line and "another CANopen master" in line, line
        assert "SYNC on 0x080" in line and channel in line, line
        _keeps_publishing(probe, first, joints)
    finally:
        if station.poll() is None:
            station.send_signal(signal.SIGINT)
            station.wait(10)


def test_a_second_simulated_node_given_the_same_channel_starts_no_station(
        domain_id, probe, start_node):
    channel = derive_channel(f"two_sims_{domain_id}_{os.getpid()}")
    bus = {"bus.interface": "udp_multicast", "bus.channel": channel}
    first = start_node(bus)
    joints = probe.subscribe(JointState, first.topic("joint_states"))
    probe.wait_for(lambda: len(joints) > 20, 30.0, "joint_states of the first", first)
    started = time.monotonic()
    second = start_node(bus, namespace="/b")
    line = _one_line_exit_1(second)
    assert "another CANopen master" in line and "SYNC on 0x080" in line, line
    assert time.monotonic() - started < 30
    assert "simulated station up" not in second.log()
    assert len([k for k in _children(first.proc.pid)]) >= 1  # the first's station still runs
    _keeps_publishing(probe, first, joints)
