"""A lost CAN interface comes back by itself, in process: the bridge never stops and says what
happened (docs/bus_errors.md).

The master's bus is the simulated wire behind a wrapper the test unplugs and plugs back: while
unplugged its calls fail as socketcan's do on a lost network device (``CanOperationError``,
ENETDOWN "Network is down") and opening it fails with ENODEV (a USB adapter pulled out).
Bus ERROR with the OS reason and
the joint STALE within 0.5 s of the unplug; fresh positions within 2 s of the return; the
bus OK again and the joint's level what its cycles since call for; the station configured
again; the log quiet. Moved from test/ros/test_node_lost_interface.py
(docs/testing.md); the bus status as the node builds it (support/inprocess_bus.py).
"""

from __future__ import annotations

import errno
import logging
import math
import time
from typing import Any

import can
from diagnostic_msgs.msg import DiagnosticStatus as D

from ssi_bridge.core.health import RATIO_WINDOW_S, STALE_RATIO_WARN
from ssi_bridge.exceptions import BusError
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import open_bus

PERIOD = 0.5


class Cable:
    """Whether the master's interface is unplugged."""

    unplugged = False


class UnpluggableWire(can.BusABC):
    """The master's end of the simulated wire, failing as a lost socketcan device while
    :attr:`Cable.unplugged`."""

    def __init__(self, config: BusConfig) -> None:
        if Cable.unplugged:
            raise BusError(f"cannot open CAN bus virtual:{config.channel}: "
                           f"[Errno {errno.ENODEV}] No such device")
        self._inner = open_bus(config)
        super().__init__(channel=config.channel)
        self.channel_info = f"unpluggable {self._inner.channel_info}"

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if Cable.unplugged:
            raise can.CanOperationError("Failed to transmit: Network is down", errno.ENETDOWN)
        self._inner.send(msg, timeout)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if Cable.unplugged:
            time.sleep(0.001)
            raise can.CanOperationError("Error receiving: Network is down", errno.ENETDOWN)
        return self._inner.recv(timeout), False

    def shutdown(self) -> None:
        super().shutdown()
        self._inner.shutdown()


def _frozen_or_fresh(b: Any, since: float, frozen: float) -> list[float]:
    return [m[0] for m in b.joint_states() if m[0] > since and math.isfinite(m[2][0])
            and m[2][0] != frozen]


def _recovered(b: Any, joint: str) -> bool:
    """The joint's level has nothing of the loss left: OK, or a WARN/ERROR its own last
    RATIO_WINDOW_S of cycles call for (core/health.py: the share of SYNCs left out, at least
    STALE_RATIO_WARN), never STALE. The in-process station is starved with the test process
    on a busy machine: its answers come later than latch_bound and are rightly left out,
    which the joint's level says, at the start as after the return."""
    level = b.level(joint)
    if level == D.OK:
        return True
    if level >= D.STALE or not b.results:
        return False
    results = list(b.results)
    window = [r for r in results[-int(2 * b.rate * RATIO_WINDOW_S):]
              if r.t_sync > results[-1].t_sync - RATIO_WINDOW_S]
    left_out = sum(1 for r in window for c in r.joints if c.joint.name == joint and c.reason)
    return left_out >= STALE_RATIO_WARN * len(window)


def test_an_unplugged_interface_comes_back_without_a_restart(inprocess, caplog):
    caplog.set_level(logging.INFO, logger="ssi_bridge")
    Cable.unplugged = False
    b = inprocess(opener=UnpluggableWire)
    try:
        b.run_until(lambda: b.bus_status().level == D.OK and len(b.joint_states()) > 20, 30.0,
                    "bus OK and joint_states")
        fresh = 0.0
        for cycle in range(2):  # twice: the second loss is handled as the first
            Cable.unplugged = True
            unplugged = time.monotonic()
            b.run_until(lambda: b.level("joint1") == D.STALE
                        and b.bus_status().level == D.ERROR, 10.0, "bus ERROR and joint1 STALE")
            at = time.monotonic() - unplugged
            bus = b.bus_status()
            assert "Network is down" in bus.message, bus.message
            print(f"loss {cycle}: bus ERROR and joint STALE after {at:.3f} s: {bus.message}")
            assert at < 0.5
            time.sleep(1.5)  # a few reopen attempts fail (ENODEV) meanwhile
            # a fresh position is one that moved (the station's joint turns at 0.25 rev/s)
            published = b.joint_states()
            frozen = published[-1][2][0]
            Cable.unplugged = False
            back = time.time()
            b.run_until(lambda: bool(_frozen_or_fresh(b, back, frozen)), 10.0,
                        "fresh joint_states after the interface came back")
            fresh = _frozen_or_fresh(b, back, frozen)[0]
            print(f"loss {cycle}: fresh positions {fresh - back:.3f} s after the return")
            assert fresh - back < 2.0
            b.run_until(lambda: b.bus_status().level == D.OK and _recovered(b, "joint1"),
                        2 * PERIOD + 5, "bus OK and joint1 recovered from the loss")
        # configured again after each return (the station never lost its NMT state)
        b.run_until(lambda: b.client.counters.configurations >= 3, 2 * PERIOD + 5,
                    "the station configured again after each return")
        figures = b.master.link_figures()
        assert figures["interface_losses"] == 2 and figures["interface_reopens"] == 2, figures
        lines = [r.getMessage() for r in caplog.records]
        assert not [r for r in caplog.records if r.exc_info], "no traceback"
        assert sum("lost: [Errno 100]" in m for m in lines) == 2, lines[-20:]
        assert sum("open again after" in m for m in lines) == 2, lines[-20:]
        assert len(lines) < 60, lines
    finally:
        Cable.unplugged = False
