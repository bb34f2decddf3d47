"""The node's simulated station(s): started, watched, faulted and stopped for the node.

The node imports this package only with ``simulation.enabled: true`` (its one import of the
simulator, docs/architecture.md); a node on real hardware loads nothing of ``ssi_bridge.sim``.
Everything here reaches the station over CAN, as the node does: :meth:`Simulation.start`
starts the ``station`` program as a child process (or the station in-process on the virtual
bus), :meth:`Simulation.open_bus` opens the master's end of the simulated wire (frames take
their time on it at the bit rate), and :meth:`Simulation.fault_injector` writes the
simulation-only objects 0x4000-0x4002 through the master's SDO client.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import can

from ssi_bridge.protocol.encoder_config import EncoderConfig
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import open_bus
from ssi_bridge.sim.supervisor.faults import FaultInjector, ObjectWriter, StationFaults
from ssi_bridge.sim.supervisor.settings import AnySettings, NodeSettings
from ssi_bridge.sim.supervisor.station import (
    ChildStation, InProcessStation, StationGroup, start_stations, with_station_bus,
)


class Simulation:
    """The simulated stations of one node, on the bus of ``settings`` (after
    :meth:`bus_settings`)."""

    def __init__(self, settings: NodeSettings) -> None:
        self.settings = settings
        self.stations: ChildStation | InProcessStation | StationGroup | None = None

    @staticmethod
    def bus_settings(settings: AnySettings, node: str,
                     domain: int | None = None) -> AnySettings:
        """``settings`` with the bus the node ``node`` (its fully qualified name) in DDS domain
        ``domain`` (default: ``ROS_DOMAIN_ID``) shares with its simulated stations."""
        return with_station_bus(settings, node, domain)

    @staticmethod
    def open_bus(config: BusConfig) -> can.BusABC:
        """The master's end of the simulated wire (a python-can bus like any other).

        :param config: the bus the master was configured with (the simulated wire's channel)
        """
        return open_bus(config)

    def start(self) -> None:
        """Start the station(s) and wait for their boot-up (GatewayUnavailable, BusError)."""
        self.stations = start_stations(self.settings)

    @property
    def pid(self) -> int | None:
        """Process id of the (first) station child, None in-process or before the start."""
        return self.stations.pid if self.stations is not None else None

    def problem(self) -> str | None:
        """Why a station is not running (its process ended), or None."""
        return self.stations.problem() if self.stations is not None else None

    def stop(self) -> None:
        """Stop every station (idempotent)."""
        if self.stations is not None:
            self.stations.stop()

    def fault_injector(self, clients: Mapping[int, ObjectWriter],
                       configs: Mapping[str, EncoderConfig | None],
                       clock: Callable[[], float]) -> FaultInjector | StationFaults:
        """Fault injection over the master's SDO clients (one per station node id).

        :param clients: the master's SDO access per station node id
        :param configs: each joint's encoder layout (None: the joint has no frame layout)
        :param clock: the monotonic clock fault durations are measured on
        """
        s = self.settings
        injectors = {sid: FaultInjector(client, {j.name: j for j in s.station_joints(sid)},
                                        dict(configs), clock)
                     for sid, client in clients.items()}
        if len(injectors) == 1:
            return next(iter(injectors.values()))
        return StationFaults(injectors, {j.name: j for j in s.joints})


__all__ = ["Simulation"]
