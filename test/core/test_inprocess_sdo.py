"""``~/sdo_read`` / ``~/sdo_write``'s handlers (ros/sdo_services.py over core/sdo_access.py)
against the simulated station in process: typed object access (CiA 301).

Values are decoded by the EDS's type (or the one named): 0x6C01 "Work area low limit" is the
INTEGER32 view of REG_LOWER_LIMIT (48), so a negative value written there reads back negative
and the register holds its two's complement. A missing object is the station's own abort
0x06020000. And docs/node.md's ``~/sdo_write`` example leaves the joint OK (read from the
page itself, so page and test cannot drift apart), while the trap it warns about (a negative
lower limit: the module compares unsigned, 000 "Lower limit, upper limit") leaves it WARN.

Moved from test/ros/test_node_sdo.py and test/ros/test_node_sdo_example.py
(docs/testing.md); the node keeps the device-type read with its ~/events entry (the ROS wiring
of both services) and the listen-only refusal (a node mode).
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticStatus as D
from ssi_bridge_msgs.srv import SdoRead, SdoWrite

WORK_AREA_LOW, REG_LOWER_LIMIT = 0x6C01, 48
DOC = Path(__file__).resolve().parents[2] / "docs" / "node.md"
PERIOD = 0.5


def _read(b, **fields):
    return b.sdo.read(SdoRead.Request(**fields), SdoRead.Response())


def _write(b, **fields):
    return b.sdo.write(SdoWrite.Request(**fields), SdoWrite.Response())


def test_sdo_read_of_a_missing_object_gives_the_abort_and_its_meaning(inprocess):
    b = inprocess()
    res = _read(b, index=0x1234, subindex=0)
    assert not res.success
    assert res.abort_code == 0x0602_0000, res.message
    assert "not exist" in res.abort_meaning.lower(), res.abort_meaning
    assert "0x06020000" in res.message, res.message
    # an object of the EDS with a subindex the station does not have
    sub = _read(b, index=0x6820, subindex=9)
    assert not sub.success and sub.abort_code == 0x0609_0011, sub.message


def test_the_motion_epoch_reads_as_unsigned64_and_places_every_published_position(inprocess):
    # 0x4004 (docs/canopen.md): the wire time in us at which the simulated shafts' motion time
    # is 0; with it and the node's parameters the truth oracle knows where the encoder was at
    # each stamp (header.stamp = the SYNC latch, docs/node.md)
    from support.truth import TruthOracle, samples_from_joint_states

    b = inprocess()
    res = _read(b, index=0x4004)
    assert res.success and res.data_type == "UNSIGNED64", res.message
    epoch = res.unsigned_value / 1e6
    assert time.time() - 600 < epoch < time.time(), epoch
    b.run_until(lambda: len(b.joint_states()) >= 50, 20.0, "50 joint_states")
    oracle = TruthOracle.from_params({"joints": ["joint1"]}, epoch)  # the node's defaults
    report = oracle.check(samples_from_joint_states(b.joint_states()[:50]))
    assert report.checked == 50 and report.ok, report.summary()


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
def test_sdo_write_refusals_name_the_reason(inprocess, fields, words):
    b = inprocess()
    res = _write(b, **fields)
    assert not res.success and words in res.message, res.message
    assert not b.errors, b.errors  # a refusal, not an internal error


def test_sdo_write_of_a_negative_integer32_reads_back_equal(inprocess):
    b = inprocess()
    write = _write(b, index=WORK_AREA_LOW, subindex=1, signed_value=-123456)
    assert write.success and write.data_type == "INTEGER32", write.message
    back = _read(b, index=WORK_AREA_LOW, subindex=1)
    assert back.success and back.data_type == "INTEGER32", back.message
    assert back.signed_value == -123456, back.message
    named = _read(b, index=WORK_AREA_LOW, subindex=1, data_type="UNSIGNED32")
    assert named.unsigned_value == (-123456) & 0xFFFF_FFFF, named.message
    # one truth: the object is the register (000 Table 16: 6C01 <-> REG_LOWER_LIMIT)
    reg = b.bridge.read_register(b.bridge.joint(""), REG_LOWER_LIMIT)  # ~/read_register
    assert reg == (-123456) & 0xFFFF_FFFF, reg


def test_a_cam_object_write_moves_the_cam_state_at_once(inprocess):
    # the node re-reads the CAM objects only every diagnostics_period: the state in ~/status
    # follows the write at once because the write reads them back (000 Table 42)
    b = inprocess({"joints": ["j"], "j.motion.kind": "still", "j.motion.start": 1.25})
    for index, fields in ((0x6B10, {"signed_value": 10000}), (0x6B20, {"signed_value": 20000}),
                          (0x6B01, {"unsigned_value": 1})):
        res = _write(b, index=index, subindex=1, **fields)
        assert res.success, res.message
    assert "CAM state follows" in res.message, res.message
    count = len(b.status_msgs)
    b.run_until(lambda: len(b.status_msgs) > count + 5, 10.0, "~/status after the writes")
    latest = b.status_msgs[-1].channels[0]
    assert latest.cam_enabled and latest.cam_state == 1, (latest.cam_enabled, latest.cam_state)


def test_node_id_picks_the_station_and_0_the_joints(inprocess):
    # 0x1014 COB-ID EMCY = 0x80 + the station's node id (CiA 301): it says who answered
    b = inprocess({"joints": ["a", "b"], "stations": [1, 3], "a.station": 1, "b.station": 3,
                   "a.slot": 1, "b.slot": 1})
    for fields, station in (({}, 1), ({"joint": "b"}, 3), ({"node_id": 3}, 3),
                            ({"node_id": 1, "joint": "b"}, 1)):
        res = _read(b, index=0x1014, **fields)
        assert res.success and res.unsigned_value == 0x80 + station, (fields, res.message)
        assert f"of node {station}" in res.message, res.message


def _documented_write() -> dict:
    """The request of docs/node.md's ``ros2 service call ... SdoWrite`` example."""
    match = re.search(r"sdo_write ssi_bridge_msgs/srv/SdoWrite \\\n\s*\"(\{[^\"]*\})\"",
                      DOC.read_text(encoding="utf-8"))
    assert match, "no ~/sdo_write example in docs/node.md"
    return yaml.safe_load(match.group(1))  # YAML reads 0x6C01 as ros2 service call does


def test_the_documented_sdo_write_leaves_the_joint_ok(inprocess):
    request = _documented_write()
    assert request["index"] == 0x6C01, request
    b = inprocess()
    b.run_until(lambda: b.level("joint1") == D.OK, 20.0, "joint1 OK")
    res = _write(b, **request)
    assert res.success, res.message
    back = _read(b, index=request["index"], subindex=request["subindex"])
    assert back.success and back.signed_value == request["signed_value"], back.message
    written = time.monotonic()
    # the module has the limit and the joint is OK with it: STS_UFLW clear, level OK
    b.run_until(lambda: b.level("joint1") == D.OK and not b.channel("joint1").sts_uflw
                and time.monotonic() - written > 2 * PERIOD, 10.0,
                "the joint OK with the documented lower limit")
    assert "STS_UFLW" not in b.status("joint1").message


def test_a_negative_lower_limit_is_the_documented_trap(inprocess):
    # -1000 as INTEGER32 is 0xFFFFFC18: every REG_SSI_POS is below it (unsigned, 000)
    b = inprocess()
    b.run_until(lambda: b.level("joint1") == D.OK, 20.0, "joint1 OK")
    assert _write(b, index=0x6C01, subindex=1, signed_value=-1000).success
    b.run_until(lambda: b.level("joint1") == D.WARN, 2 * PERIOD + 5, "joint1 WARN")
    count = len(b.status_msgs)
    b.run_until(lambda: len(b.status_msgs) > count + 100, 10.0, "a second of ~/status")
    assert all(m.channels[0].sts_uflw for m in b.status_msgs[count:]), "STS_UFLW cleared"
    assert b.level("joint1") == D.WARN
    assert "STS_UFLW" in b.status("joint1").message
    # 0 switches the lower limit off again (000: the default, no monitoring)
    assert _write(b, index=0x6C01, subindex=1, signed_value=0).success
    b.run_until(lambda: b.level("joint1") == D.OK, 2 * PERIOD + 5, "joint1 OK again")
