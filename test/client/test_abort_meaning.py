"""SDO abort meanings come from canopen, the codes the simulated gateway raises from protocol/.

Every named code of ``protocol/aborts.py`` (CiA 301 v4.2 Table 22) must have canopen's text, so
a refusal of the gateway always reaches a user with its meaning (a canary for the canopen
version: a release that dropped one of them fails here).
"""

from __future__ import annotations

import pytest

from ssi_bridge.client.sdo import abort_meaning
from ssi_bridge.protocol.aborts import SdoAbort


@pytest.mark.parametrize("code", list(SdoAbort), ids=lambda c: c.name)
def test_every_named_abort_code_has_a_meaning(code):
    assert "not defined" not in abort_meaning(code)


def test_an_unknown_code_says_so():
    assert "0x12345678 is not defined by CiA 301" in abort_meaning(0x12345678)


def test_object_does_not_exist():
    assert "does not exist" in abort_meaning(SdoAbort.NO_SUCH_OBJECT).lower()
