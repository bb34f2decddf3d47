"""Bridges in different namespaces do not meet on one bus by accident.

Two nodes with the same parameters (``bus.channel`` included), started as the launch file's
``namespace`` argument starts them (``-r __ns:=/a``, ``/b``): each simulated station gets a
udp_multicast group and port derived from the node's fully qualified name as well, so both
bridges come up and publish, each its own joint_states and its own /diagnostics names. Before,
both stations came up on the same derived group, each master saw the other's station boot,
and both exited 1 (a CAN bus has one master, CiA 301).
"""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState


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
    assert a.proc.poll() is None and b.proc.poll() is None
    for node in (a, b):
        assert "did not answer" not in node.log(), node.log()[-2000:]
