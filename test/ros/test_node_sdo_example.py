"""docs/node.md's ``~/sdo_write`` example, run against the node: the joint ends OK.

The example writes the work area's low limit 0x6C01 (= REG_LOWER_LIMIT, 000 Table 16) of the
first joint. The module compares REG_SSI_POS with its limits as unsigned 32-bit numbers (000
"Lower limit, upper limit": defaults 0x00000000 and 0xFFFFFFFF, "set by default to the maximum
and minimum value"; STS_UFLW = 1 when "(REG_SSI_POS) < (REG_LOWER_LIMIT)"), so the example
the page used to give, ``signed_value: -1000``, was the lower limit 0xFFFFFC18 and left the
joint WARN (STS_UFLW) for good. The page's example is read from the page itself, so page and
test cannot drift apart; the trap it now warns about is checked as well.
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from ssi_bridge_msgs.msg import Status
from ssi_bridge_msgs.srv import SdoRead, SdoWrite

from .conftest import latest_status, wait_for_level

DOC = Path(__file__).resolve().parents[2] / "docs" / "node.md"
PERIOD = 0.5
JOINT = "/ssi_bridge: joint1"


def _documented_write() -> dict:
    """The request of the page's ``ros2 service call ... SdoWrite`` example."""
    match = re.search(r"sdo_write ssi_bridge_msgs/srv/SdoWrite \\\n\s*\"(\{[^\"]*\})\"",
                      DOC.read_text(encoding="utf-8"))
    assert match, "no ~/sdo_write example in docs/node.md"
    return yaml.safe_load(match.group(1))  # YAML reads 0x6C01 as ros2 service call does


def _write(probe, node, **fields):
    res = probe.call(SdoWrite, node.topic("~/sdo_write"), SdoWrite.Request(**fields))
    assert res.success, res.message
    return res


def test_the_documented_sdo_write_leaves_the_joint_ok(running, probe):
    request = _documented_write()
    assert request["index"] == 0x6C01, request
    node = running({"diagnostics_period": PERIOD})
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    status = probe.subscribe(Status, node.topic("~/status"))
    wait_for_level(probe, node, diags, JOINT, DiagnosticStatus.OK, 20.0)
    _write(probe, node, **request)
    back = probe.call(SdoRead, node.topic("~/sdo_read"),
                      SdoRead.Request(index=request["index"], subindex=request["subindex"]))
    assert back.success and back.signed_value == request["signed_value"], back.message
    written = time.monotonic()
    # the module has the limit and the joint is OK with it: STS_UFLW clear, level OK
    probe.wait_for(lambda: latest_status(diags, JOINT) is not None
                   and latest_status(diags, JOINT).level == DiagnosticStatus.OK
                   and status and not status[-1][1].channels[0].sts_uflw
                   and time.monotonic() - written > 2 * PERIOD, 10.0,
                   "the joint OK with the documented lower limit", node)
    assert "STS_UFLW" not in latest_status(diags, JOINT).message


def test_a_negative_lower_limit_is_the_documented_trap(running, probe):
    # -1000 as INTEGER32 is 0xFFFFFC18: every REG_SSI_POS is below it (unsigned, 000)
    node = running({"diagnostics_period": PERIOD})
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    status = probe.subscribe(Status, node.topic("~/status"))
    wait_for_level(probe, node, diags, JOINT, DiagnosticStatus.OK, 20.0)
    _write(probe, node, index=0x6C01, subindex=1, signed_value=-1000)
    wait_for_level(probe, node, diags, JOINT, DiagnosticStatus.WARN, 2 * PERIOD + 5)
    count = len(status)
    probe.wait_for(lambda: len(status) > count + 100, 10.0, "a second of ~/status", node)
    assert all(m.channels[0].sts_uflw for _t, m in status[count:]), "STS_UFLW cleared"
    assert latest_status(diags, JOINT).level == DiagnosticStatus.WARN
    assert "STS_UFLW" in latest_status(diags, JOINT).message
    # 0 switches the lower limit off again (000: the default, no monitoring)
    _write(probe, node, index=0x6C01, subindex=1, signed_value=0)
    wait_for_level(probe, node, diags, JOINT, DiagnosticStatus.OK, 2 * PERIOD + 5)
