"""What the node's parts read of the node: small structural types, each part's whole view.

The node (``ros/node.py``) owns its parts (bus side, diagnostics, run-time parameters,
lifecycle, services, recording, live view) and hands each one what it needs at construction.
What changes over the node's life (the cycle an activate builds, the settings a parameter
change replaces) is read through a protocol the node meets with its own attributes: a part
sees those members, typed, and nothing else of the node.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Protocol

import can

from ssi_bridge.client.master import BridgeClient
from ssi_bridge.core.ports import FaultPort
from ssi_bridge.protocol.encoder_config import EncoderConfig
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.ros.cycle import CycleThread
from ssi_bridge.ros.observe import ObservedCycleThread
from ssi_bridge.ros.params import NodeSettings

#: the node's cycle loop: SYNC master, or observer of another master's SYNC
CycleLoop = CycleThread | ObservedCycleThread
#: one step of a shutdown: (what, callable); a failing step is logged, the next still runs
Step = tuple[str, Callable[[], object]]


class SimulatedStation(Protocol):
    """The node's simulated station(s) (``sim/supervisor``'s ``Simulation``), as the node
    uses them; the node imports the simulator only with ``simulation.enabled: true``."""

    def open_bus(self, config: BusConfig) -> can.BusABC:
        """The master's end of the simulated wire."""

    def start(self) -> None:
        """Start the station(s) and wait for their boot-up.

        :raises GatewayUnavailable: a station did not boot
        :raises BusError: the simulated wire cannot be opened
        """

    def stop(self) -> None:
        """Stop every station (idempotent)."""

    def problem(self) -> str | None:
        """Why a station is not running (its process ended), or None."""

    def fault_injector(self, clients: Mapping[int, BridgeClient],
                       configs: Mapping[str, EncoderConfig | None],
                       clock: Callable[[], float]) -> FaultPort:
        """Fault injection over the master's SDO clients (one per station node id)."""


class NodeView(Protocol):
    """What the diagnostics read of the node beside its bus side: the settings as they are
    now, the cycle loop and the latch bound."""

    @property
    def settings(self) -> NodeSettings:
        """The node's settings as they are now (a run-time parameter change replaces them)."""

    @property
    def cycle(self) -> CycleLoop | None:
        """The cycle loop while the node is active (None: not activated yet, deactivated)."""

    @property
    def latch_bound_s(self) -> float:
        """The longest a sample's frames may end after its SYNC to be published (s)."""


__all__ = ["CycleLoop", "NodeView", "SimulatedStation", "Step"]
