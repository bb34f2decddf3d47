"""``~/sdo_read`` / ``~/sdo_write`` against the installed node: typed object access (CiA 301).

Values are decoded by the EDS's type (or the one named): 0x1000 is UNSIGNED32 0x00000191 (the
gateway's CiA 401 device type, docs/canopen.md), 0x6C01 "Work area low limit" is the INTEGER32
view of REG_LOWER_LIMIT (48), so a negative value written there reads back negative and the
register holds its two's complement. A missing object is the station's own abort 0x06020000.
The REG_PARA1 path (0x5801 moves <joint>.para1 and the scale) is checked beside the other
REG_PARA1 paths in test_node_live.py.
"""

from __future__ import annotations

import pytest
from ssi_bridge_msgs.msg import Event, Status
from ssi_bridge_msgs.srv import ReadRegister, SdoRead, SdoWrite

WORK_AREA_LOW, REG_LOWER_LIMIT = 0x6C01, 48
LISTEN_ONLY = "listen-only: another master drives this bus"


def _read(probe, node, **fields):
    return probe.call(SdoRead, node.topic("~/sdo_read"), SdoRead.Request(**fields))


def _write(probe, node, **fields):
    return probe.call(SdoWrite, node.topic("~/sdo_write"), SdoWrite.Request(**fields))


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


def test_sdo_read_of_a_missing_object_gives_the_abort_and_its_meaning(shared_node, shared_probe):
    node = shared_node()
    res = _read(shared_probe, node, index=0x1234, subindex=0)
    assert not res.success
    assert res.abort_code == 0x0602_0000, res.message
    assert "not exist" in res.abort_meaning.lower(), res.abort_meaning
    assert "0x06020000" in res.message, res.message
    # an object of the EDS with a subindex the station does not have
    sub = _read(shared_probe, node, index=0x6820, subindex=9)
    assert not sub.success and sub.abort_code == 0x0609_0011, sub.message


@pytest.mark.parametrize("fields, words", [
    ({"index": 0x1800, "subindex": 1, "unsigned_value": 0x181}, "PDO parameters"),
    ({"index": 0x1017, "unsigned_value": 10}, "heartbeat"),
    ({"index": 0x2100, "subindex": 1, "unsigned_value": 1}, "~/write_register"),
    ({"index": 0x4002, "unsigned_value": 1}, "~/inject_fault"),
    ({"index": 0x6C01, "subindex": 1, "data_type": "INTEGER8", "signed_value": 300},
     "outside INTEGER8"),
    ({"index": 0x6C01, "subindex": 1, "data_type": "FLOAT99"}, "not one of"),
    ({"index": 0x1234, "unsigned_value": 1}, "not in the EDS"),
    ({"node_id": 9, "index": 0x6C01, "subindex": 1}, "node id 9 is not a station"),
    ({"joint": "nope", "index": 0x6C01, "subindex": 1}, "unknown joint"),
    ({"index": 0x5801, "subindex": 1, "unsigned_value": 0x21010000}, "SSI_FRAME_LEN"),
])
def test_sdo_write_refusals_name_the_reason(shared_node, shared_probe, fields, words):
    node = shared_node()  # a refusal changes nothing: one node serves every case
    res = _write(shared_probe, node, **fields)
    assert not res.success and words in res.message, res.message


def test_sdo_write_of_a_negative_integer32_reads_back_equal(running, probe):
    node = running()
    write = _write(probe, node, index=WORK_AREA_LOW, subindex=1, signed_value=-123456)
    assert write.success and write.data_type == "INTEGER32", write.message
    back = _read(probe, node, index=WORK_AREA_LOW, subindex=1)
    assert back.success and back.data_type == "INTEGER32", back.message
    assert back.signed_value == -123456, back.message
    named = _read(probe, node, index=WORK_AREA_LOW, subindex=1, data_type="UNSIGNED32")
    assert named.unsigned_value == (-123456) & 0xFFFF_FFFF, named.message
    # one truth: the object is the register (000 Table 16: 6C01 <-> REG_LOWER_LIMIT)
    reg = probe.call(ReadRegister, node.topic("~/read_register"),
                     ReadRegister.Request(address=REG_LOWER_LIMIT))
    assert reg.success and reg.value == (-123456) & 0xFFFF_FFFF, reg.message


def test_a_cam_object_write_moves_the_cam_state_at_once(running, probe):
    # the node re-reads the CAM objects only every diagnostics_period (60 s here): the state
    # in ~/status follows the write at once because the write reads them back (000 Table 42)
    node = running({"joints": ["j"], "j.motion.kind": "still", "j.motion.start": 1.25,
                    "diagnostics_period": 60.0})
    status = probe.subscribe(Status, node.topic("~/status"))
    for index, fields in ((0x6B10, {"signed_value": 10000}), (0x6B20, {"signed_value": 20000}),
                          (0x6B01, {"unsigned_value": 1})):
        res = _write(probe, node, index=index, subindex=1, **fields)
        assert res.success, res.message
    assert "CAM state follows" in res.message, res.message
    count = len(status)
    probe.wait_for(lambda: len(status) > count + 5, 10.0, "~/status after the writes", node)
    latest = status[-1][1].channels[0]
    assert latest.cam_enabled and latest.cam_state == 1, (latest.cam_enabled, latest.cam_state)


def test_node_id_picks_the_station_and_0_the_joints(running, probe):
    # 0x1014 COB-ID EMCY = 0x80 + the station's node id (CiA 301): it says who answered
    node = running({"joints": ["a", "b"], "stations": [1, 3], "a.station": 1, "b.station": 3,
                    "a.slot": 1, "b.slot": 1})
    for fields, station in (({}, 1), ({"joint": "b"}, 3), ({"node_id": 3}, 3),
                            ({"node_id": 1, "joint": "b"}, 1)):
        res = _read(probe, node, index=0x1014, **fields)
        assert res.success and res.unsigned_value == 0x80 + station, (fields, res.message)
        assert f"of node {station}" in res.message, res.message


def test_sdo_services_are_refused_listen_only(start_node, probe):
    node = start_node({"simulation.enabled": False, "bus.listen_only": True})
    res = probe.call(SdoRead, node.topic("~/sdo_read"), SdoRead.Request(index=0x1000),
                     timeout=30.0)
    assert not res.success and LISTEN_ONLY in res.message, res.message
    res = probe.call(SdoWrite, node.topic("~/sdo_write"),
                     SdoWrite.Request(index=0x6C01, subindex=1, signed_value=1))
    assert not res.success and LISTEN_ONLY in res.message, res.message
