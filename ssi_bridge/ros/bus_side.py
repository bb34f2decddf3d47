"""The node's bus side: what a configure opens and a cleanup closes.

A simulated station (with ``simulation.enabled``: a device of its own, a child process or
in-process on the virtual bus, reached only over CAN, fault injection included through SDO
0x4000-0x4002), then either the listener of a listen-only node (and the player of a
``replay.can_log``) or the CANopen master with one client per station, each joint's module
configured as a master does at start-up. The node (``ros/node.py``) owns one
:class:`BusSide` for its whole life and reads its members; the joints' cores and frame logs
are the node's.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

from ssi_bridge.client.bus_master import CanMaster
from ssi_bridge.client.can_log_player import CanLogPlayer
from ssi_bridge.client.listener import ListenOnlyClient
from ssi_bridge.client.master import BridgeClient
from ssi_bridge.client.one_master import ensure_node_alone
from ssi_bridge.core.bridge import Bridge
from ssi_bridge.core.joint import Joint
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.ros import logbridge
from ssi_bridge.ros.messages import idle_read
from ssi_bridge.ros.node_ports import SimulatedStation, Step
from ssi_bridge.ros.params import NodeSettings

#: starts the simulated station(s) of the node's settings (the supervisor's ``Simulation``)
StationFactory = Callable[[NodeSettings], SimulatedStation]


class BusSide:
    """The station(s), the master and its clients, or the listener, while configured.

    :param bus_config: the node's bus
    :param simulation: makes the simulated station(s) (None: real hardware)
    :param bridge: the facade: its fault port is set here, each joint configured through it
    :param clock: the simulated station's clock (fault durations, s)
    :param info: an INFO log line (a joint's start-up configuration changed the module)
    """

    def __init__(self, bus_config: BusConfig, simulation: StationFactory | None,
                 bridge: Bridge, clock: Callable[[], float],
                 info: Callable[[str], object]) -> None:
        self._config = bus_config
        self._simulation = simulation
        self._bridge = bridge
        self._clock = clock
        self._info = info
        #: the simulated station(s) while open (simulation: true), else None
        self.station: SimulatedStation | None = None
        #: the CANopen master (None: listen-only, or closed)
        self.master: CanMaster | None = None
        #: one client per station (node id -> client), all on one master: one SYNC per cycle
        self.station_clients: dict[int, BridgeClient] = {}
        #: the first station's client or the listener (None before the first open; kept,
        #: closed, after a close)
        self.client: BridgeClient | ListenOnlyClient | None = None
        #: the log replay of a listen-only node (``replay.can_log``), not started
        self.player: CanLogPlayer | None = None

    def open(self, s: NodeSettings, joints: Mapping[str, Joint]) -> None:
        """Start the simulated station (if any), check that no other master serves the
        stations, then connect the listener or the master and its clients and configure
        ``joints``' modules.

        What is open when this raises stays for :meth:`close_steps`.

        :raises SsiBridgeError: a station did not boot or answer, another master serves the
            stations, the bus cannot be opened (GatewayUnavailable, BusError, ConfigError)
        :raises OSError: the replay's log cannot be read
        """
        self._bridge.faults = None
        self.station = self._simulation(s) if self._simulation is not None else None
        ensure_node_alone(self._config, s,
                          self.station.open_bus if self.station is not None else None)
        if self.station is not None:
            self.station.start()
        self.player = None
        self.station_clients = {}
        self.master = None
        if s.listen_only:
            listener = ListenOnlyClient(self._config, s.node_id, max(j.slot for j in s.joints))
            self.client = listener
            listener.connect()
            if s.replay_can_log:
                self.player = CanLogPlayer(s.replay_can_log, s.bus_channel, rate=s.replay_rate)
        else:
            self._connect_stations(s, joints)

    def _connect_stations(self, s: NodeSettings, joints: Mapping[str, Joint]) -> None:
        """The master, one client per station, and each joint's start-up configuration."""
        station = self.station
        master = self.master = CanMaster(
            self._config, priority=s.cycle_priority,
            opener=station.open_bus if station is not None else None)
        for sid in s.station_ids:  # a failure: configure closes what is open (lifecycle.py)
            slots = max(j.slot for j in s.station_joints(sid))
            self.station_clients[sid] = BridgeClient(master, sid, slots,
                                                     sdo_timeout=s.bus_sdo_timeout)
            # our own station booted just now: on a busy machine its first answer may be late
            self.station_clients[sid].connect(
                patience=s.simulation_start_timeout if station is not None else 0.0)
        self.client = self.station_clients[s.station_ids[0]]
        if station is not None:
            self._bridge.faults = station.fault_injector(
                self.station_clients, {n: j.config for n, j in joints.items()}, self._clock)
        for joint in joints.values():
            change = self._bridge.configure(joint, idle_read)
            if change:
                self._info(f"{logbridge.clip(joint.name, 80)}: {change}")

    def close_steps(self) -> list[Step]:
        """The steps that close every station's client, the bus, the master and stop the
        simulated station; the side lets go of the station, the master and the clients (the
        last client stays, closed, for a late reader)."""
        steps: list[Step] = [(f"station {sid} client", c.close)
                             for sid, c in self.station_clients.items()]
        if self.client is not None:
            steps.append(("bus", self.client.close))
        if self.master is not None:
            steps.append(("master", self.master.close))
        if self.station is not None:
            steps.append(("simulated station", self.station.stop))
        self.station, self.station_clients, self.master = None, {}, None
        return steps


__all__ = ["BusSide", "StationFactory"]
