"""The in-process tier: the node's bus side and its simulated station in one process, no DDS.

What the node composes at start (``ros/node.py`` ``_open_bus_side``) minus ROS: the simulated
station (``sim/gateway/station.py``, its own device, reached only over CAN) on a private
python-can ``virtual`` channel, the master (``client``: :class:`CanMaster`, one
:class:`BridgeClient` per station), each joint's core (``core/joint.py``), each station's frame
log fed by its slot table, the cycle core (``core/cycle.py``), the services' facade
(``core/bridge.py``) with the fault injector the node gives it (``sim/supervisor/faults.py``,
SDO 0x4000-0x4002 over the master's client). A cycle, on the node's cycle loop
(``ros/cycle.py`` ``CycleThread``): expire the faults, SYNC, wait for the TPDOs
(``cycle_waits``), decide every joint and settle the SYNC before (``Cycle.run``). The node
decides a complete cycle in the receive thread that handled its last TPDO instead
(``ros/cycle_publish.py``), with the same core and rules; what differs is which thread.

Tests of the driver's behaviour on the bus use this instead of a node process, as canopen's
own tests drive a ``LocalNode`` against a ``RemoteNode``; what the node adds (topics, QoS,
services, parameters, lifecycle, recording, signals) stays with the node-process tests. The
joint's diagnostic status is built by the node's own function (``ros/diagnostics.py``
``channel_status``, no rclpy), so its level and message are the ones the node publishes.
"""

from __future__ import annotations

import dataclasses
import itertools
import os
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from ssi_bridge.base.timebase import ModelClock
from ssi_bridge.client.cycle_feed import feed_frames, sync_number
from ssi_bridge.client.master import BridgeClient, CanMaster
from ssi_bridge.core.bridge import Bridge
from ssi_bridge.core.cycle import Cycle, CycleResult
from ssi_bridge.core.cycle_log import StationLog
from ssi_bridge.core.joint import Joint
from ssi_bridge.protocol import wire
from ssi_bridge.protocol.registers import Reg
from ssi_bridge.protocol.settings import (
    STATION_DEFAULTS, BusConfig, JointSettings, StationSettings, make_joints,
)
from ssi_bridge.sim.gateway.bus import open_bus
from ssi_bridge.sim.gateway.station import Station
from ssi_bridge.sim.supervisor.faults import FaultInjector, StationFaults

#: the node's defaults (ros/param_table.py): velocity_window, stale_cycles, latch_bound,
#: publish_rate, bus.sdo_timeout
VELOCITY_WINDOW, STALE_CYCLES, LATCH_BOUND, PUBLISH_RATE, SDO_TIMEOUT = 5, 5, 0.002, 100.0, 0.5
#: SCHED_FIFO priorities of the node's cycle and receive threads (cycle_priority) and of its
#: simulated station (simulation.station_priority); normal scheduling where not permitted
CYCLE_PRIORITY, STATION_PRIORITY = 5, 10
#: the register the node keeps in REG_RD_ADR while no handshake runs (ros/messages.py)
IDLE_READ_REGISTER = int(Reg.REG_SSI_FRAME)
_channels = itertools.count()


def idle_read(out: bytearray) -> None:
    """The node's idle process output: byte 4 = REG_RD_ADR = REG_SSI_FRAME (docs/node.md)."""
    out[4] = IDLE_READ_REGISTER


@dataclass
class InProcessBridge:
    """A started station and the master's side wired to it as the node wires them.

    :param values: node parameter values with dotted names (``joints``, ``<joint>.family``,
        ``<joint>.para1``, ``<joint>.max_speed``, ``publish_rate``...), as a params file gives
        them; absent ones take the node's defaults. ``bus.channel`` is made private.
    """

    values: Mapping[str, Any] = field(default_factory=dict)
    #: opens the master's bus (default: the master's end of the simulated wire)
    opener: Callable[[BusConfig], Any] | None = None
    #: the simulated stations by node id, first station first
    stations: dict[int, Station] = field(init=False, default_factory=dict)
    master: CanMaster = field(init=False)
    clients: dict[int, BridgeClient] = field(init=False, default_factory=dict)
    joints: dict[str, Joint] = field(init=False, default_factory=dict)
    logs: dict[int, StationLog] = field(init=False, default_factory=dict)
    cycle: Cycle = field(init=False)
    bridge: Bridge = field(init=False)
    faults: FaultInjector | StationFaults = field(init=False)
    clock: ModelClock = field(init=False, default_factory=ModelClock)
    #: the results of every cycle run so far
    results: list[CycleResult] = field(init=False, default_factory=list)
    #: the ~/status message of each of those cycles (``ros/messages.py`` ``status_msg``)
    status_msgs: list[Any] = field(init=False, default_factory=list)
    #: (SYNC wire time, each joint's level) of every cycle: when a level changed
    levels: list[tuple[float, dict[str, int]]] = field(init=False, default_factory=list)
    #: the service events (kind, joint, request, success, message), as ~/events has them
    service_events: list[tuple[str, str, str, bool, str]] = field(init=False,
                                                                  default_factory=list)
    #: each joint's ``<joint>.para1`` parameter as the node mirrors it from the module
    para1: dict[str, int] = field(init=False, default_factory=dict)
    #: unexpected errors the service handlers logged
    errors: list[str] = field(init=False, default_factory=list)

    def __post_init__(self) -> None:
        self._findings: Any = None
        values = {**STATION_DEFAULTS, **self.values, "bus.interface": "virtual",
                  "bus.channel": f"inprocess-{os.getpid()}-{next(_channels)}"}
        self.bus = BusConfig(interface="virtual", channel=str(values["bus.channel"]),
                             bitrate=int(values["bus.bitrate"]), node_id=int(values["bus.node_id"]))
        self.frame_id = str(values.get("frame_id", ""))
        self.rate = float(values.get("publish_rate", PUBLISH_RATE))
        self.settings = self._joints_by_station(values)
        counts = [max(j.slot for j in joints) for joints in self.settings.values()]
        self.wire_s = wire.frame_seconds(wire.stations_cycle_bits(counts), self.bus.bitrate)
        # as the node does at start (ros/node.py _start): the GIL goes to a waiting thread
        # (the station's, the master's receive thread) within a quarter of a cycle
        self._switch = sys.getswitchinterval()
        sys.setswitchinterval(min(self._switch, 0.25 / self.rate))
        try:
            for sid, joints in self.settings.items():
                station = Station(StationSettings(joints=joints, bus=dataclasses.replace(
                    self.bus, node_id=sid)))
                # its receive thread answers the SYNCs above the cycle, as the node's
                # in-process fallback sets it (sim/supervisor/station.py InProcessStation)
                station.gateway.rx_priority = STATION_PRIORITY
                self.stations[sid] = station
                station.start()
            self._open_master(values)
        except BaseException:
            self.close()
            raise

    def _joints_by_station(self, values: Mapping[str, Any]) -> dict[int, tuple[JointSettings, ...]]:
        """Each station's joints as the node's parameters give them (ros/params.py): the
        station reads slot, family, para1, motion...; the node adds ``<joint>.station``
        (``stations``, default ``bus.node_id``) and ``<joint>.ssi_mask``."""
        names = [str(n) for n in values["joints"]]
        ids = [int(i) for i in values.get("stations") or [self.bus.node_id]]
        station_of = {n: int(values.get(f"{n}.station", 0)) or ids[0] for n in names}
        out = {}
        for sid in ids:
            own = make_joints([n for n in names if station_of[n] == sid], values)
            out[sid] = tuple(dataclasses.replace(
                j, station=sid, ssi_mask=int(values.get(f"{j.name}.ssi_mask", -1)))
                for j in own)
        return out

    def _open_master(self, values: Mapping[str, Any]) -> None:
        self.master = CanMaster(self.bus, priority=CYCLE_PRIORITY, opener=self.opener or open_bus)
        names = [str(n) for n in values["joints"]]
        by_name = {j.name: j for joints in self.settings.values() for j in joints}
        for name in names:  # the configured order
            self.joints[name] = Joint(
                by_name[name], velocity_window=int(values.get("velocity_window", VELOCITY_WINDOW)),
                stale_cycles=int(values.get("stale_cycles", STALE_CYCLES)),
                max_speed=float(values.get(f"{name}.max_speed", -1.0)))
        injectors = {}
        for sid, joints in self.settings.items():
            client = BridgeClient(self.master, sid, max(j.slot for j in joints),
                                  sdo_timeout=float(values.get("bus.sdo_timeout", SDO_TIMEOUT)))
            self.clients[sid] = client
            client.connect(patience=5.0)
            log = StationLog(float(values.get("latch_bound", LATCH_BOUND)) + self.wire_s,
                             slots=tuple(j.slot for j in joints))
            feed_frames(client, log)
            self.logs[sid] = log
            injectors[sid] = FaultInjector(client, {j.name: j for j in joints},
                                           {n: j.config for n, j in self.joints.items()},
                                           self.clock)
        self.cycle = Cycle(self.joints, self.logs)
        self.bridge = Bridge(self.joints, self.client_of, self._mirror_para1)
        self.faults = (next(iter(injectors.values())) if len(injectors) == 1
                       else StationFaults(injectors, by_name))
        self.bridge.faults = self.faults
        from ssi_bridge.core.sdo_access import ObjectAccess
        from ssi_bridge.ros.sdo_services import SdoServices  # rclpy-free handlers

        #: ~/sdo_read and ~/sdo_write's handlers (``.read(request, response)``, ``.write``)
        self.sdo = SdoServices(ObjectAccess(self.bridge), self._log_event, self.errors.append)
        for joint in self.joints.values():
            self.bridge.configure(joint, idle_read)
        self.bridge.refresh_cams()
        from ssi_bridge.ros.cycle import CycleThread  # rclpy-free: the node's own loop

        self._loop = CycleThread(1.0 / self.rate, self._cycle, name="inprocess_cycle",
                                 priority=CYCLE_PRIORITY)
        self._loop.start()

    def _mirror_para1(self, joint: str, value: int) -> None:
        """What the node mirrors into ``<joint>.para1`` (ros/node_params.py)."""
        self.para1[joint] = value

    def _log_event(self, kind: str, joint: str, request: str, success: bool,
                   message: str) -> None:
        self.service_events.append((kind, joint, request, success, message))

    def joint_states(self) -> list[tuple[float, list[str], list[float], list[float]]]:
        """(stamp s, names, positions, velocities) of each cycle's joint_states as the node
        publishes them (``header.stamp`` = the SYNC's wire time, only the published joints;
        a cycle without one sends none): what ``support.truth`` reads."""
        out = []
        for result in list(self.results):
            parts = [p for p in result.published if p.output is not None]
            if parts:
                out.append((result.t_sync, [p.joint.name for p in parts],
                            [p.output.position for p in parts],
                            [p.output.velocity for p in parts]))
        return out

    def joint_state_msgs(self) -> list[Any]:
        """Each cycle's joint_states message as the node builds it (``ros/messages.py``
        ``joint_state_msg``, stamped with the SYNC's wire time, ``frame_id``); a cycle
        without a published joint sends none."""
        from ssi_bridge.base.timebase import to_ros_ns
        from ssi_bridge.ros.messages import joint_state_msg, time_msg

        out = []
        for result in list(self.results):
            msg = joint_state_msg(result, time_msg(to_ros_ns(result.t_sync)), self.frame_id)
            if msg.name:
                out.append(msg)
        return out

    def station_status(self, node_id: int) -> Any:
        """Station ``node_id``'s DiagnosticStatus as ``ros/node_status.py`` builds it for
        several stations (``ros/diagnostics.py`` ``station_status``: heartbeat, NMT state,
        EMCY history)."""
        from ssi_bridge.ros.diagnostics import station_status

        client = self.clients[node_id]
        node = client.node
        emcy = ([f"0x{e.code:04X} reg 0x{e.register:02X} {e.get_desc()}".strip()
                 for e in node.emcy.log] if node is not None else [])
        return station_status(f"station {node_id}", "inprocess", alive=client.gateway_alive,
                              nmt_state=str(node.nmt.state if node is not None else "UNKNOWN"),
                              emcy=emcy, counters={})

    def client_of(self, joint: str) -> BridgeClient:
        """The client of the station holding ``joint``'s module (KeyError: unknown joint)."""
        return self.clients[self.joints[joint].settings.station]

    @property
    def station(self) -> Station:
        """The (first) simulated station."""
        return next(iter(self.stations.values()))

    @property
    def client(self) -> BridgeClient:
        """The (first) station's client."""
        return next(iter(self.clients.values()))

    def _cycle(self) -> None:
        """One cycle as the node's cycle thread runs it (``ros/node.py`` ``_cycle``), on the
        node's cycle loop (``ros/cycle.py`` ``CycleThread``) at ``publish_rate``."""
        from ssi_bridge.ros.cycle import cycle_waits  # rclpy-free: the node's own waits
        from ssi_bridge.ros.messages import status_msg  # ROS message types, no rclpy
        from std_msgs.msg import Header

        self.faults.expire()
        t_sync = self.client.sync()
        self.master.wait_cycle(*cycle_waits(1.0 / self.rate, self.wire_s))
        result = self.cycle.run(sync_number(self.client, t_sync), t_sync)
        self.results.append(result)
        self.levels.append((t_sync, {name: j.level for name, j in self.joints.items()}))
        # ~/status reads the joints' counters as they are now: built each cycle, as the node
        self.status_msgs.append(status_msg(result, Header()))

    def run_for(self, seconds: float) -> list[CycleResult]:
        """Let the cycles run for ``seconds``; the results of those cycles."""
        first = len(self.results)
        time.sleep(seconds)
        return self.results[first:]

    def run_until(self, condition: Callable[[], bool], timeout: float, what: str) -> None:
        """Wait while the cycles run until ``condition()`` holds; AssertionError naming
        ``what`` after ``timeout`` s."""
        end = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > end:
                raise AssertionError(f"no {what} within {timeout} s")
            time.sleep(0.02)  # the condition reads the joints: little GIL for it

    def status(self, joint: str) -> Any:
        """The joint's DiagnosticStatus as the node builds it (``ros/diagnostics.py``
        ``channel_status`` of the core's counters and health, the para1 note added as
        ``ros/node_status.py`` adds it)."""
        from ssi_bridge.core.health import WARN
        from ssi_bridge.ros.diagnostics import channel_status

        j = self.joints[joint]
        extra = {"para1": f"0x{j.para1:08X}", "max_speed": f"{j.max_speed:g}"}  # as the node
        st = channel_status(joint, "inprocess", j.counters, j.health, j.position, extra)
        if j.para1_note:
            st.message = j.para1_note if st.level < WARN else f"{st.message}; {j.para1_note}"
            st.level = max(st.level, WARN)
        return st

    def channel(self, joint: str) -> Any:
        """The joint's ~/status ChannelStatus of the newest cycle that has its image; None
        before any."""
        for msg in reversed(self.status_msgs):
            for ch in msg.channels:
                if ch.joint == joint:
                    return ch
        return None

    def channels(self, joint: str) -> list[Any]:
        """Every ChannelStatus of ``joint`` so far, one per cycle that had its image."""
        return [ch for msg in self.status_msgs for ch in msg.channels if ch.joint == joint]

    def events(self) -> list[tuple[str, bool, str]]:
        """(joint, success, sentence) of every ``~/events`` entry of kind ``encoder_status``
        the cycles so far gave (the node logs each published output's events)."""
        return [(part.joint.name, ok, text) for result in self.results
                for part in result.published if part.output is not None
                for ok, text in part.output.events]

    def bus_status(self) -> Any:
        """A bus DiagnosticStatus as the node builds it (support/inprocess_bus.py); each call
        is one diagnostics message: what grew since the call before is a WARN naming it."""
        from ssi_bridge.ros.node_status import BusFindings
        from support.inprocess_bus import node_bus_status

        if self._findings is None:
            self._findings = BusFindings(lambda: self.master, lambda: 1.0)
        return node_bus_status(self, self._findings)

    def level(self, joint: str) -> bytes:
        """The level byte of :meth:`status` (``DiagnosticStatus.OK`` ...)."""
        return self.status(joint).level

    def close(self) -> None:
        """Stop the cycles, close the master's side and stop the station (idempotent)."""
        loop = getattr(self, "_loop", None)
        if loop is not None:
            loop.stop()
        for client in self.clients.values():
            client.close()
        master = getattr(self, "master", None)
        if master is not None:
            master.close()
        for station in self.stations.values():
            station.stop()
        sys.setswitchinterval(self._switch)


def values_of(st: Any) -> dict[str, str]:
    """A DiagnosticStatus's key/values as a dict."""
    return {kv.key: kv.value for kv in st.values}


__all__ = ["IDLE_READ_REGISTER", "InProcessBridge", "idle_read", "values_of"]
