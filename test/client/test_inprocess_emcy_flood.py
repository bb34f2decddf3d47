"""An EMCY flood from a flapping module is logged one line per second per slot and code, in
process (client/emcy_log.py through the master's client; the master and the simulated
station on the virtual bus: test/support/inprocess.py).

The default REG_PARA1 (25-bit binary) on a 30-bit Gray AFM60: the module's SSI error bit
flaps, and the gateway sends an EMCY 0x7000 / 0x0000 pair per flap (000 chapter 4
"Additional emergencies"). Moved from test/ros/test_node_logs.py (docs/testing.md): the same
counts on the log records the node's logger bridge prints (ros/logbridge.py; the node's log
wiring: test_node_logs.py's other tests).
"""

from __future__ import annotations

import logging
import re
import time

import pytest

from support.inprocess import InProcessBridge

MASTER_LOGGER = "ssi_bridge.client.master"


@pytest.fixture
def flapping(caplog: pytest.LogCaptureFixture):
    caplog.set_level(logging.INFO, logger="ssi_bridge")
    b = InProcessBridge({"joint1.family": "AFM60_MULTI", "publish_rate": 1000.0})
    try:
        yield b, caplog
    finally:
        b.close()


def test_emcy_floods_are_one_line_per_second_per_slot_and_code(flapping):
    _b, caplog = flapping

    def emcy() -> list[logging.LogRecord]:
        return [r for r in list(caplog.records) if "EMCY" in r.getMessage()]

    deadline = time.monotonic() + 60.0
    while (sum("more in the last" in r.getMessage() for r in emcy()) < 4
           and time.monotonic() < deadline):
        time.sleep(0.1)
    records = emcy()
    text = [r.getMessage() for r in records]
    assert len([m for m in text if "more in the last" in m]) >= 4, text[-10:]
    hidden = sum(int(n) for m in text for n in re.findall(r"and (\d+) more", m))
    assert hidden > len(records), "edges were summarised, not printed"
    for key in ("EMCY 0x7000 slot 1: SSI error", "EMCY 0x0000 error reset"):
        times = [r.created for r in records if key in r.getMessage()]
        assert all(b - a >= 0.99 for a, b in zip(times, times[1:])), (key, times)
    assert all(r.name == MASTER_LOGGER and r.levelno == logging.INFO for r in records)
    gateway = [r for r in caplog.records if r.name == "ssi_bridge.sim.gateway.emergency"
               and r.levelno >= logging.INFO]
    assert not gateway, "the gateway side logs at DEBUG"
