"""``~/sdo_read`` / ``~/sdo_write`` against the installed node: the services' ROS wiring.

0x1000 reads as UNSIGNED32 0x00000191 (the gateway's CiA 401 device type, docs/canopen.md)
and is an ``~/events`` entry; listen-only, both services are refused. What the handlers do
with objects, types, aborts and refusals runs in process: test/core/test_inprocess_sdo.py
(docs/testing.md). The REG_PARA1 path (0x5801 moves <joint>.para1 and the scale) is checked
beside the other REG_PARA1 paths in test_node_live.py.
"""

from __future__ import annotations

from ssi_bridge_msgs.msg import Event
from ssi_bridge_msgs.srv import SdoRead, SdoWrite

LISTEN_ONLY = "listen-only: another master drives this bus"


def _read(probe, node, **fields):
    return probe.call(SdoRead, node.topic("~/sdo_read"), SdoRead.Request(**fields))


def test_sdo_read_of_the_device_type_is_unsigned32_and_an_event(shared_node, shared_probe):
    node = shared_node()
    events = shared_probe.subscribe(Event, node.topic("~/events"))
    res = _read(shared_probe, node, index=0x1000)
    assert res.success, res.message
    assert (res.data_type, res.unsigned_value, res.abort_code) == ("UNSIGNED32", 0x191, 0)
    assert "Device type" in res.message, res.message
    named = _read(shared_probe, node, index=0x1000, data_type="unsigned16")
    assert not named.success and "4 byte(s); UNSIGNED16 is 2" in named.message, named.message
    shared_probe.wait_for(lambda: any(m.kind == "sdo_read" and "index=0x1000" in m.request
                                      and m.success for _, m in events),
                          10.0, "the sdo_read event", node)


def test_sdo_services_are_refused_listen_only(start_node, probe):
    node = start_node({"simulation.enabled": False, "bus.listen_only": True})
    res = probe.call(SdoRead, node.topic("~/sdo_read"), SdoRead.Request(index=0x1000),
                     timeout=30.0)
    assert not res.success and LISTEN_ONLY in res.message, res.message
    res = probe.call(SdoWrite, node.topic("~/sdo_write"),
                     SdoWrite.Request(index=0x6C01, subindex=1, signed_value=1))
    assert not res.success and LISTEN_ONLY in res.message, res.message
