"""The bus status of the in-process bridge as the node builds it (ros/node_status.py), and the
node's diagnostics timer: one bus status every period, kept in order.

The status is ``ros/diagnostics.py`` ``bus_status`` of the client's liveness and the same
counters the node gives it (the client's counters, late frames, the master's link, error-frame
and load figures), with the node's error beside the bus state (a lost interface, a bus-off
controller) and ``ros/node_status.py`` ``BusFindings`` applied: what grew since the last
status is a WARN naming it. ROS message types only, no rclpy.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from typing import Any

from ssi_bridge.ros.diagnostics import bus_status
from ssi_bridge.ros.node_status import BusFindings


def node_bus_status(b: Any, findings: BusFindings) -> Any:
    """One bus DiagnosticStatus of the in-process bridge ``b`` (one station), as the node's
    ``NodeDiagnostics`` makes it; ``findings`` keeps the counters of the status before."""
    client, master = b.client, b.master
    counters: dict[str, Any] = dataclasses.asdict(client.counters)
    counters["late_frames"] = client.table.late_frames
    counters.update(master.link_figures())
    counters.update(master.error_frames.figures())
    counters.update(client.load.figures())
    problem = "; ".join(p for p in (master.interface_problem(), master.error_frames.problem())
                        if p)
    return findings.applied(bus_status(
        "bus", f"virtual:{b.bus.channel} node {b.bus.node_id} XN-GW-CANOPEN",
        alive=client.gateway_alive, connected=client.network is not None,
        achieved_rate=b.rate, publish_rate=b.rate, counters=counters, extra_error=problem),
        counters)


class BusDiagnostics:
    """The node's diagnostics timer for the bus status: every ``period`` s one status,
    appended to :attr:`history` as (monotonic time, status); stop with :meth:`stop`."""

    def __init__(self, b: Any, period: float) -> None:
        self._b = b
        self._findings = BusFindings(lambda: b.master, lambda: period)
        self.period = period
        self.history: list[tuple[float, Any]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="inprocess_diag", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self.period):
            self.history.append((time.monotonic(), node_bus_status(self._b, self._findings)))

    def latest(self) -> Any:
        """The newest status (None before the first)."""
        return self.history[-1][1] if self.history else None

    def values(self) -> dict[str, str]:
        """The newest status's key/values ({} before the first)."""
        st = self.latest()
        return {kv.key: kv.value for kv in st.values} if st is not None else {}

    def stop(self) -> None:
        """End the timer."""
        self._stop.set()
        self._thread.join(2 * self.period + 1)


__all__ = ["BusDiagnostics", "node_bus_status"]
