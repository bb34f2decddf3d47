"""The in-process bridge held to the truth (support/truth.py), as support/node_truth.py's
``Run`` holds a node: every published sample against the simulated encoder's true position
at its stamp, within one count plus the stated latch bound.

In process every cycle's joint_states is seen (no subscriber can fall behind), so every
finite velocity is checked. The object has what support/node_changes.py's ``timed`` and
``hold_changes`` use (``phase``, ``received_until``, ``samples``, ``hold``, ``oracle``,
``bound``).
"""

from __future__ import annotations

import time
from typing import Any

from support.inprocess import LATCH_BOUND, InProcessBridge
from support.truth import TruthOracle, samples_from_joint_states

#: object 0x4004: the simulated shafts' motion epoch (wire time in us, docs/canopen.md)
SIM_EPOCH = 0x4004
#: support/node_truth.py's run: one joint at 200 Hz
RATE = 200.0


class TruthRun:
    """An in-process bridge of ``values`` with its oracle and its stated bound (the node's
    ``latch_bound_s``: latch_bound plus one cycle's wire time)."""

    def __init__(self, bridge: InProcessBridge, values: dict[str, Any]) -> None:
        from diagnostic_msgs.msg import DiagnosticStatus

        self.b, self.params = bridge, values
        names = list(values.get("joints", ["joint1"]))
        self.first = names[0]
        for name in names:
            bridge.run_until(lambda n=name: bridge.level(n) == DiagnosticStatus.OK, 20.0,
                             f"{name} OK")
        epochs = {sid: int(client.read_object(SIM_EPOCH, 0)) / 1e6
                  for sid, client in bridge.clients.items()}
        #: each station's motion epoch (wire time, s), by node id
        self.epochs = epochs
        self.oracle = TruthOracle.from_params(values, epochs)
        self.bound = float(values.get("latch_bound", LATCH_BOUND)) + bridge.wire_s
        #: (wire time, name) of each disturbance started
        self.phases: list[tuple[float, str]] = []

    def received_until(self, wire: float) -> None:
        """Nothing to wait for: in process every cycle's result is kept as the cycle ends
        (``support.node_truth.Run.received_until`` waits for a probe's subscriptions)."""

    def samples(self) -> list[Any]:
        """Every sample published so far."""
        return samples_from_joint_states(self.b.joint_states())

    def hold(self, samples: list[Any], oracle: TruthOracle, case: str = "",
             t0: float | None = None) -> None:
        """``samples`` hold the rule against ``oracle``; a failure lists the worst."""
        report = oracle.check(samples, self.bound)
        assert report.checked > 0
        phases = "".join(f"\n  phase {name!r} from {w:.3f}" for w, name in self.phases)
        assert report.ok, f"{case}: " + report.summary() + phases

    def check(self, case: str = "") -> None:
        """Every sample published so far holds the rule."""
        self.hold(self.samples(), self.oracle, case)

    def phase(self, name: str) -> None:
        """A disturbance starts now (wire time), for the failure message."""
        self.phases.append((time.time(), name))

    def set_aside_during(self, w0: float, w1: float) -> set[str]:
        """The reasons ~/status gives for the first joint left out of the cycles whose SYNC
        went out in [w0, w1] (wire time)."""
        return {part.reason for r in list(self.b.results) if w0 <= r.t_sync <= w1
                for part in r.joints if part.joint.name == self.first and part.output is None}


__all__ = ["RATE", "SIM_EPOCH", "TruthRun"]
