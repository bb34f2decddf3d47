"""Bridges in different namespaces do not meet on one bus by accident.

Two nodes with the same parameters (``bus.channel`` included), started as the launch file's
``namespace`` argument starts them (``-r __ns:=/a``, ``/b``): each simulated station gets a
udp_multicast group and port derived from the node's fully qualified name as well, so both
bridges come up and publish, each its own joint_states and its own /diagnostics names
(``<node FQN>: <item>``, each naming its own hardware). Before,
both stations came up on the same derived group, each master saw the other's station boot,
and both exited 1 (a CAN bus has one master, CiA 301). The same for one bridge started on two
``ROS_DOMAIN_ID``s: the derived group and port depend on the domain too.
"""

from __future__ import annotations

import os
import re
import time

from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState

from ..conftest import claim_domain
from .conftest import launch_node


def test_two_bridges_in_namespaces_both_publish(start_node, probe, domain_id):
    same = {"bus.channel": f"shared_{domain_id}", "diagnostics_period": 0.5}
    a = start_node(same, namespace="/a")
    b = start_node(same, namespace="/b")
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    joints_a = probe.subscribe(JointState, a.topic("joint_states"))
    joints_b = probe.subscribe(JointState, b.topic("joint_states"))
    probe.wait_for(lambda: len(joints_a) > 10, 30.0, "joint_states of /a", a)
    probe.wait_for(lambda: len(joints_b) > 10, 30.0, "joint_states of /b", b)

    def buses() -> dict[str, str]:
        return {st.name: st.hardware_id for _t, m in diags for st in m.status
                if st.name.endswith(": bus")}
    probe.wait_for(lambda: {"/a/ssi_bridge: bus", "/b/ssi_bridge: bus"} <= set(buses()),
                   10.0, "the bus statuses of both bridges", a)
    names = {st.name for _t, m in diags for st in m.status}
    assert {"/a/ssi_bridge: joint1", "/b/ssi_bridge: joint1"} <= names, names
    hw = buses()
    assert hw["/a/ssi_bridge: bus"] != hw["/b/ssi_bridge: bus"], hw  # two buses, not one
    # each status names its own hardware (from test_node_diagnostics.py, merged here: the
    # same two namespaced bridges)
    hw = {st.name: st.hardware_id for _t, m in diags for st in m.status}
    assert hw["/a/ssi_bridge: joint1"] != hw["/b/ssi_bridge: joint1"], hw
    assert "slot 1" in hw["/a/ssi_bridge: joint1"], hw
    assert "node 1" in hw["/b/ssi_bridge: bus"], hw
    assert a.proc.poll() is None and b.proc.poll() is None
    for node in (a, b):
        assert "did not answer" not in node.log(), node.log()[-2000:]


def test_the_same_bridge_on_two_domains_runs_twice(start_node, tmp_path, child_preexec):
    """Robots (and CI jobs) are kept apart by ROS_DOMAIN_ID: two nodes of the same name and
    parameters on two domains each get a bus of their own, so the second does not hear the
    first's SYNC and exit 1 ("another CANopen master drives ...")."""
    same = {"bus.channel": f"domains_{os.getpid()}"}
    a = start_node(same)
    other, claim = claim_domain()
    try:
        (tmp_path / "other").mkdir()
        b = launch_node(tmp_path / "other", other, 1, child_preexec, same)
        try:
            for node in (a, b):
                node.wait_for_log("bridging")
            time.sleep(2.0)  # the one-master check and a few hundred cycles
            assert a.proc.poll() is None and b.proc.poll() is None, (a.log()[-2000:],
                                                                     b.log()[-2000:])
            for node in (a, b):
                assert "another CANopen master" not in node.log(), node.log()[-2000:]
                assert "not sent by this master" not in node.log(), node.log()[-2000:]
            buses = [re.search(r"on udp_multicast:(\S+) node", n.log()) for n in (a, b)]
            assert all(buses) and buses[0][1] != buses[1][1], [m and m[1] for m in buses]
        finally:
            assert b.stop() == 0, b.log()[-2000:]
    finally:
        os.close(claim)
