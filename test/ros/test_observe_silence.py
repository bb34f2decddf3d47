"""A listen-only bridge on a silent bus says so once (ros/observe.py, rclpy-free), in process:
the listener (client/listener.py) on a private virtual bus no master drives, observed by the
node's ``ObservedCycleThread`` as the node starts it for ``bus.listen_only`` (ros/node.py:
the silent-bus warning after ``SILENT_WARNING_S``). Moved from test/ros/test_node_logs.py
(docs/testing.md).
"""

from __future__ import annotations

import logging
import os
import time

from ssi_bridge.client.listener import ListenOnlyClient
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.ros.observe import SILENT_WARNING_S, ObservedCycleThread


def test_listen_only_on_a_silent_bus_says_so(caplog):
    caplog.set_level(logging.INFO, logger="ssi_bridge")
    client = ListenOnlyClient(BusConfig(interface="virtual",
                                        channel=f"silent-{os.getpid()}"), 1, 1)
    client.connect()
    quiet: list[float] = []
    loop = ObservedCycleThread(client, 0.01, lambda _cycle: None,
                               lambda: quiet.append(time.monotonic()))
    started = time.monotonic()
    loop.start()
    try:
        deadline = started + SILENT_WARNING_S + 30.0
        while not any("no SYNC on the bus" in r.getMessage() for r in caplog.records):
            assert time.monotonic() < deadline, "no silent-bus warning"
            time.sleep(0.05)
        assert time.monotonic() - started >= SILENT_WARNING_S - 1.0, \
            "not before the documented time"
        time.sleep(1.0)  # more silent periods: still one warning
    finally:
        loop.stop()
        client.close()
    warnings = [r for r in caplog.records if "no SYNC on the bus" in r.getMessage()]
    assert len(warnings) == 1, "one warning, not one per period"
    assert warnings[0].levelno == logging.WARNING and quiet, "quiet cycles went on"
