"""The node's /diagnostics: a status per joint, the bus, and each station when there are several.

:class:`NodeDiagnostics` is the node's diagnostics part (``ros/node.py`` owns it): it reads the
joints, the bus side (``ros/bus_side.py``), the cycle (:class:`~ssi_bridge.ros.node_ports.
NodeView`), the figures of the recorder, the live view and the services, and publishes
through the node's shutdown-safe publish. The levels and messages come from the per-joint core
(``core/joint.py``, ``core/health.py``) and ``ros/diagnostics.py`` puts them into
``diagnostic_msgs``. Published every ``diagnostics_period`` and at once when a level changes
(checked each cycle, cheaply). :class:`BusFindings` says what the bus did between two
messages; :class:`CycleRate` measures the achieved cycle rate.
"""

from __future__ import annotations

import dataclasses
import time
from collections import deque
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from ssi_bridge.base.realtime import fifo_meanwhile
from ssi_bridge.client.bus_master import CanMaster
from ssi_bridge.client.error_frames import error_frame_keys
from ssi_bridge.client.listener import ListenOnlyClient
from ssi_bridge.client.master import BridgeClient
from ssi_bridge.core.cycle import Cycle
from ssi_bridge.core.health import ERROR, WARN, Level
from ssi_bridge.core.joint import Joint
from ssi_bridge.ros.cycle import CycleThread
from ssi_bridge.ros.diagnostics import bus_status, channel_status, station_status, status_name
from ssi_bridge.ros.bus_side import BusSide
from ssi_bridge.ros.node_ports import NodeView
from ssi_bridge.ros.stamps import Stamper

if TYPE_CHECKING:
    from rclpy.node import Node

    from ssi_bridge.ros.liveview import LiveView
    from ssi_bridge.ros.recording import SessionRecorder
    from ssi_bridge.ros.services import BridgeServices


#: bus counters whose growth since the last diagnostics message is a WARN: what the bus did
#: that the receive path survived, another node's SYNC or NMT commands, stations restarted
BUS_WARN_COUNTS = ("undecodable_frames", "malformed_pdos", "malformed_frames", "receive_errors",
                   "callback_errors", "invalid_nmt_states", "nmt_restarts", "foreign_syncs",
                   "foreign_nmt_commands", "foreign_station_frames")
#: and an ERROR: a round of a station's supervisor thread failed (it goes on; the log says why)
BUS_ERROR_COUNT = "supervisor_errors"
#: the bus status's figures: counter name -> value (a count, a figure, a text)
Figures = dict[str, object]
#: the periodic diagnostics sleep this long (s) between the parts they build, so that the
#: receive thread, when it waits for Python's lock meanwhile, takes it then instead of after
#: the switch interval (5 ms); long enough for a waiting thread to wake and take it
YIELD_S = 20e-6


class CycleRate:
    """Cycles per second over a window, from each cycle's monotonic time (an interval measure,
    not the SYNC stamps).

    The cycle appends ``time.monotonic()`` to :attr:`times` once per cycle it ran.
    """

    def __init__(self) -> None:
        #: the monotonic time of each cycle of the window (and some older ones, dropped lazily)
        self.times: deque[float] = deque()
        #: when the cycle (re)started: the window never reaches back before it
        self.started = time.monotonic()

    def restart(self) -> None:
        """A new bus side: forget the cycles and count from now."""
        self.times.clear()
        self.started = time.monotonic()

    def per_second(self, period_s: float) -> float:
        """Cycles per second over the last ``period_s`` (at least 1 s, at most since
        :attr:`started`); 0.0 right at the start."""
        now = time.monotonic()
        window = min(max(period_s, 1.0), now - self.started)
        if window <= 0:
            return 0.0
        times = self.times
        while times and now - times[0] > window:
            times.popleft()
        return len(times) / window


class BusFindings:
    """What the bus did between two diagnostics messages, as a level and a message.

    :param master: the node's master now (None: listen-only or closed: no foreign-traffic or
        error-frame findings)
    :param period_s: the diagnostics period now (s): foreign frames of two periods count
    """

    def __init__(self, master: Callable[[], CanMaster | None],
                 period_s: Callable[[], float]) -> None:
        self._master = master
        self._period_s = period_s
        self._last: dict[str, int] = {}

    def reset(self) -> None:
        """A new bus side: every counter starts from zero again."""
        self._last = {}

    def findings(self, counters: Mapping[str, object]) -> tuple[Level | None, str]:
        """What the bus did since the last call: (level, message), or (None, "").

        Counters of :data:`BUS_WARN_COUNTS` and error frames of a class (``error_frames_*``)
        that grew, a controller error passive or warning, and other nodes' SYNC / NMT / SDO
        request frames of the last two periods are a WARN; a failed supervisor round an ERROR.
        """
        names = (*BUS_WARN_COUNTS, *error_frame_keys(), BUS_ERROR_COUNT)
        now = {k: _count(counters.get(k, 0)) for k in names}
        last = self._last
        grown = {k: now[k] - last.get(k, 0) for k in names if now[k] > last.get(k, 0)}
        self._last = now
        if grown.get(BUS_ERROR_COUNT):
            return ERROR, (f"bridge-supervisor thread: {grown[BUS_ERROR_COUNT]} round(s) "
                           "failed (see the log)")
        parts = [f"{k} +{n}" for k, n in grown.items()]
        master = self._master()
        if master is not None:
            foreign = master.foreign_traffic(2 * self._period_s())
            passive = master.error_frames.warning()  # error passive / warning
            parts += [p for p in (passive, foreign) if p]
        return (WARN, "; ".join(parts)) if parts else (None, "")

    def applied(self, status: DiagnosticStatus,
                counters: Mapping[str, object]) -> DiagnosticStatus:
        """``status`` raised to the level of :meth:`findings` where that is worse; a status
        already as bad keeps its message and gets the findings after it (a low cycle rate must
        not hide the undecodable frames that came with it)."""
        level, message = self.findings(counters)
        if level is None:
            return status
        if status.level < level:
            status.level, status.message = level, message
        else:
            status.message = f"{status.message}; {message}"
        return status


def _count(value: object) -> int:
    """A counter's value as a count (the bus status's counters are ints or bools)."""
    return int(value) if isinstance(value, (int, float)) else 0


class NodeDiagnostics:
    """The node's /diagnostics (see the module docstring).

    :param node: the node whose name the statuses carry, whose clock stamps the message and
        whose context says whether publishing still makes sense
    :param view: the node's settings and cycle as they are now
    :param bus: the node's bus side (read while it is open)
    :param joints: the joints' cores by name (the node's own mapping, refilled per configure)
    :param rate: the achieved cycle rate (the cycle feeds it)
    :param cycle_core: the cycle decisions (its incomplete cycles)
    :param stamper: the header stamps (its clock steps)
    :param recorder: gives its figures and error; records the message
    :param liveview: gives its figures and error
    :param services: gives the busy refusals and the request worker's rest
    :param publish: publishes a DiagnosticArray on ``/diagnostics``; False when the node is
        shutting down
    :param refresh_cams: re-reads every joint's CAM objects (SDO)
    :param bus_open: whether the bus side is open (the periodic message waits for it)
    """

    def __init__(self, node: Node, view: NodeView, bus: BusSide, joints: Mapping[str, Joint],
                 rate: CycleRate, cycle_core: Cycle, stamper: Stamper, *,
                 recorder: SessionRecorder, liveview: LiveView, services: BridgeServices,
                 publish: Callable[[DiagnosticArray], bool],
                 refresh_cams: Callable[[], None], bus_open: Callable[[], bool]) -> None:
        self._node = node
        self._view = view
        self._bus = bus
        self._bus_open = bus_open
        self._joints = joints
        self._rate = rate
        self._cycle_core = cycle_core
        self._stamper = stamper
        self._recorder = recorder
        self._liveview = liveview
        self._services = services
        self._publish = publish
        self._refresh_cams = refresh_cams
        self.bus = BusFindings(lambda: bus.master, lambda: view.settings.diagnostics_period)
        self._last_levels: list[object] = []

    def reset(self) -> None:
        """A new bus side: no level to compare with, every bus counter from zero."""
        self._last_levels = []
        self.bus.reset()

    def achieved_rate(self) -> float:
        """Cycles per second over the last diagnostics period (at least 1 s, at most uptime)."""
        return self._rate.per_second(self._view.settings.diagnostics_period)

    def _levels(self) -> list[object]:
        """The diagnostic levels without building the statuses (checked every cycle).

        One flat list, no object per joint: a joint's level, then its frame findings as one
        number (PowerFail 2, encoder error 1). PowerFail / error bits change a joint's level
        too (a failed check under noise would flip it every few cycles: that one waits for the
        periodic message). No check (a register read holds REG_RD_ADR) raises nothing, as a
        clean one: not a change, or every ~/read_register would publish the diagnostics
        twice. Then each station's heartbeat, the first client's with whether the bus has a
        problem, and whether another producer's SYNC was seen lately."""
        levels: list[object] = []
        append = levels.append
        for joint in self._joints.values():
            append(joint.level)
            frame = joint.counters.frame
            append(0 if frame is None else 2 * frame.power_failure + frame.encoder_error)
        for client in self._bus.station_clients.values():
            append(client.gateway_alive)
        append(int(self._client().gateway_alive) * 2 + self._has_bus_problem())
        # another producer's SYNC makes the bus WARN (BusFindings) and takes the cycles: at
        # once, over the window the bus findings use (no message per foreign SYNC)
        master = self._bus.master
        append(master is not None and master.foreign_sync_within(
            2 * self._view.settings.diagnostics_period))
        return levels

    def publish_on_change(self) -> None:
        """Publish the diagnostics at once when a level changed since the last call (each
        cycle)."""
        levels = self._levels()
        if self._last_levels and levels != self._last_levels:
            self.publish()
        self._last_levels = levels

    def _client(self) -> BridgeClient | ListenOnlyClient:
        """The bus side's (first) client; RuntimeError before the first configure."""
        if (client := self._bus.client) is None:
            raise RuntimeError("diagnostics of a bus side never opened")
        return client

    def _statuses(self, yielding: bool = False) -> list[DiagnosticStatus]:
        """Every status of the message; ``yielding``: sleep :data:`YIELD_S` before each
        joint's and the bus's (the periodic message, on the executor thread)."""
        s = self._view.settings
        client = self._client()
        fqn = self._node.get_fully_qualified_name()
        out = []
        for joint in self._joints.values():
            hw = (f"{s.bus_interface}:{s.bus_channel} node {joint.settings.station or s.node_id} "
                  f"slot {joint.slot} XN-1SSI")
            extra = {"para1": f"0x{joint.para1:08X}",
                     "max_speed": f"{joint.max_speed:g}",
                     "velocity_window": str(s.velocity_window),
                     "stale_limit_cycles": str(s.stale_cycles),
                     "frame_id": s.frame_id}
            if yielding:
                time.sleep(YIELD_S)
            st = channel_status(status_name(fqn, joint.name), hw, joint.counters, joint.health,
                                joint.position, extra)
            if joint.para1_note:
                # the likely cause of what a worse level reports (a misread frame's error bits)
                st.message = (joint.para1_note if st.level < WARN
                              else f"{st.message}; {joint.para1_note}")
                st.level = max(st.level, WARN)
            out.append(st)
        if len(self._bus.station_clients) > 1:
            return out + self._station_statuses()
        if yielding:
            time.sleep(YIELD_S)
        counters: Figures = dataclasses.asdict(client.counters)
        counters.update(self._recorder.counters())
        counters["late_frames"] = client.table.late_frames
        counters.update(self._cycle_counters())
        if isinstance(client, BridgeClient):  # a listener has no load meter
            counters.update(client.load.figures())
        counters.update(self._liveview.counters())
        out.append(self.bus.applied(bus_status(
            status_name(fqn, "bus"),
            f"{s.bus_interface}:{s.bus_channel} node {s.node_id} XN-GW-CANOPEN",
            alive=client.gateway_alive, connected=client.network is not None,
            achieved_rate=self.achieved_rate(), publish_rate=s.publish_rate, counters=counters,
            extra_error=self.bus_problem()), counters))
        return out

    def _cycle_counters(self) -> Figures:
        """The bus status's figures of the cycle, its threads and the services (one station
        or several)."""
        view = self._view
        cycle = view.cycle
        counters: Figures = {
            "clock_steps": self._stamper.clock_steps,
            "incomplete_cycles": self._cycle_core.incomplete_cycles,
            "samples_set_aside": sum(j.counters.set_aside for j in self._joints.values()),
            "latch_bound_s": f"{view.latch_bound_s:.6f}",
            "cycles_missed": cycle.missed if isinstance(cycle, CycleThread) else 0,
            "cycle_scheduling": cycle.scheduling if cycle is not None else ""}
        master = self._bus.master
        if master is not None:
            counters["receive_scheduling"] = master.receive_scheduling
            counters.update(master.link_figures())
            counters.update(master.error_frames.figures())
        counters["diagnostics_period_s"] = f"{view.settings.diagnostics_period:g}"
        counters["service_busy_refusals"] = self._services.busy_refusals
        counters["service_rested_s"] = f"{self._services.queue.rested:.2f}"
        return counters

    def _station_statuses(self) -> list[DiagnosticStatus]:
        """Several stations: one bus status (master, SYNC, rate) and one per station."""
        s = self._view.settings
        clients = self._bus.station_clients
        fqn = self._node.get_fully_qualified_name()
        master = self._bus.master
        assert master is not None
        counters: Figures = dataclasses.asdict(master.counters)
        counters.update(self._recorder.counters())
        counters["late_frames"] = sum(c.table.late_frames for c in clients.values())
        counters.update(self._cycle_counters())
        counters.update(master.load.figures())
        silent = [sid for sid, c in clients.items() if not c.gateway_alive]
        totals = dict(counters)  # each station's supervisor counts into its own client
        for key in ("invalid_nmt_states", "nmt_restarts", BUS_ERROR_COUNT):
            totals[key] = sum(getattr(c.counters, key, 0) for c in clients.values())
        out = [self.bus.applied(bus_status(
            status_name(fqn, "bus"), f"{s.bus_interface}:{s.bus_channel} master of stations "
            f"{list(clients)}", alive=True, connected=master.network is not None,
            achieved_rate=self.achieved_rate(), publish_rate=s.publish_rate, counters=counters,
            extra_error=self.bus_problem()), totals)]
        if silent:
            out[0].values.append(KeyValue(key="silent_stations", value=str(silent)))
        for sid, client in clients.items():
            node = client.node
            nmt = node.nmt.state if node is not None else "UNKNOWN"
            emcy = ([f"0x{e.code:04X} reg 0x{e.register:02X} {e.get_desc()}".strip()
                     for e in node.emcy.log] if node is not None else [])
            station_counters = {k: v for k, v in dataclasses.asdict(client.counters).items()
                                if k not in ("frames", "syncs")}
            out.append(station_status(
                status_name(fqn, f"station {sid}"),
                f"{s.bus_interface}:{s.bus_channel} node {sid} XN-GW-CANOPEN",
                alive=client.gateway_alive, nmt_state=str(nmt), emcy=emcy,
                counters=station_counters))
        return out

    def bus_problem(self) -> str:
        """An error beside the bus state: a lost interface, a bus-off controller, the
        recorder's, the live view's, a simulated station that ended ("" when none)."""
        station, master = self._bus.station, self._bus.master
        ended = station.problem() if station is not None else None
        link = master.interface_problem() if master is not None else ""
        bus_off = master.error_frames.problem() if master is not None else ""
        return "; ".join(p for p in (link, bus_off, self._recorder.error, self._liveview.error,
                                     ended) if p)

    def _has_bus_problem(self) -> bool:
        """Whether :meth:`bus_problem` says anything, without putting it into words (each
        cycle's change test)."""
        station, master = self._bus.station, self._bus.master
        if self._recorder.error or self._liveview.error:
            return True
        if master is not None and (master.interface_problem() or master.error_frames.problem()):
            return True
        return station is not None and bool(station.problem())

    def on_timer(self) -> None:
        """Periodic diagnostics while the bus side is open; the CAM objects are re-read here
        (SDO, never in the cycle)."""
        if not self._bus_open():
            return
        master = self._bus.master
        lost = master is not None and master.interface_problem()
        # at just below the cycle's priority meanwhile: the receive thread waits for Python's
        # lock while this thread holds it, and a busy machine must not preempt it then
        priority = self._view.settings.cycle_priority
        with fifo_meanwhile(max(priority - 1, 1) if priority > 0 else 0):
            if not self._view.settings.listen_only and not lost and self._node.context.ok():
                self._refresh_cams()
            self.publish(yielding=True)

    def publish(self, yielding: bool = False) -> None:
        """Publish one DiagnosticArray with a status per joint and one for the bus (nothing
        once the context is shut down, or before use_sim_time's first /clock); ``yielding``:
        let a waiting thread have Python's lock between the parts (:data:`YIELD_S`)."""
        if not self._node.context.ok():
            return
        clock = self._node.get_clock()
        now = clock.now()
        if now.nanoseconds <= 0:
            return  # use_sim_time before the first /clock: no time to stamp with
        msg = DiagnosticArray()
        msg.header.stamp = now.to_msg()
        msg.status = self._statuses(yielding)
        if yielding:
            time.sleep(YIELD_S)
        if not self._publish(msg):
            return
        self._recorder.record("/diagnostics", msg, clock.now().nanoseconds)


__all__ = ["BUS_ERROR_COUNT", "BUS_WARN_COUNTS", "BusFindings", "CycleRate", "NodeDiagnostics"]
