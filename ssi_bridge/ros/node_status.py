"""The node's /diagnostics: a status per joint, the bus, and each station when there are several.

:class:`NodeDiagnostics` is a part of :class:`~ssi_bridge.ros.node.SsiBridgeNode` (a mixin: it
reads the node's joints, clients, cycle and recorder, and publishes on its ``diag_pub``). The
levels and messages come from the per-joint core (``core/joint.py``, ``core/health.py``) and
``ros/diagnostics.py`` puts them into ``diagnostic_msgs``. Published every
``diagnostics_period`` and at once when a level changes (checked each cycle, cheaply).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, KeyValue

from ssi_bridge.client.error_frames import error_frame_keys
from ssi_bridge.core.health import ERROR, WARN
from ssi_bridge.ros.diagnostics import bus_status, channel_status, station_status, status_name


#: bus counters whose growth since the last diagnostics message is a WARN: what the bus did
#: that the receive path survived, another node's SYNC or NMT commands, stations restarted
BUS_WARN_COUNTS = ("undecodable_frames", "malformed_pdos", "malformed_frames", "receive_errors",
                   "callback_errors", "invalid_nmt_states", "nmt_restarts", "foreign_syncs",
                   "foreign_nmt_commands", "foreign_station_frames")
#: and an ERROR: a round of a station's supervisor thread failed (it goes on; the log says why)
BUS_ERROR_COUNT = "supervisor_errors"


class NodeDiagnostics:
    """The diagnostics part of the node (see the module docstring)."""

    # provided by the node
    settings: Any
    joints: dict
    client: Any
    master: Any
    station_clients: dict
    cycle: Any
    handlers: Any
    recorder: Any
    liveview: Any
    station: Any
    diag_pub: Any
    clock_steps: int
    incomplete_cycles: int
    latch_bound_s: float
    _cycle_times: Any
    _cycle_started: float
    _last_levels: tuple
    _last_bus_counts: dict

    def _bus_findings(self, counters: dict[str, Any]) -> tuple[bytes | None, str]:
        """What the bus did since the last diagnostics message: (level, message), or (None, "").

        Counters of :data:`BUS_WARN_COUNTS` and error frames of a class (``error_frames_*``)
        that grew, a controller error passive or warning, and other nodes' SYNC / NMT / SDO
        request frames of the last two periods are a WARN; a failed supervisor round an ERROR.
        """
        names = (*BUS_WARN_COUNTS, *error_frame_keys(), BUS_ERROR_COUNT)
        last = self._last_bus_counts
        grown = {k: counters.get(k, 0) - last.get(k, 0) for k in names
                 if counters.get(k, 0) > last.get(k, 0)}
        self._last_bus_counts = {k: counters.get(k, 0) for k in names}
        if grown.get(BUS_ERROR_COUNT):
            return ERROR, (f"bridge-supervisor thread: {grown[BUS_ERROR_COUNT]} round(s) "
                           "failed (see the log)")
        parts = [f"{k} +{n}" for k, n in grown.items()]
        if self.master is not None:
            foreign = self.master.foreign_traffic(2 * self.settings.diagnostics_period)
            passive = self.master.error_frames.warning()  # error passive / warning
            parts += [p for p in (passive, foreign) if p]
        return (WARN, "; ".join(parts)) if parts else (None, "")

    def _with_bus_findings(self, status: Any, counters: dict[str, Any]) -> Any:
        """``status`` raised to the level of :meth:`_bus_findings` where that is worse; a
        status already as bad keeps its message and gets the findings after it (a low cycle
        rate must not hide the undecodable frames that came with it)."""
        level, message = self._bus_findings(counters)
        if level is None:
            return status
        if status.level < level:
            status.level, status.message = level, message
        else:
            status.message = f"{status.message}; {message}"
        return status

    def achieved_rate(self) -> float:
        """Cycles per second over the last diagnostics period (at least 1 s, at most uptime);
        the cycles' times are monotonic (an interval measure, not the SYNC stamps)."""
        now = time.monotonic()
        window = min(max(self.settings.diagnostics_period, 1.0), now - self._cycle_started)
        if window <= 0:
            return 0.0
        times = self._cycle_times
        while times and now - times[0] > window:
            times.popleft()
        return len(times) / window

    def _levels(self) -> tuple:
        """The diagnostic levels without building the statuses (checked every cycle)."""
        levels: list[Any] = [j.level for j in self.joints.values()]
        # PowerFail / error bits change a joint's level too (a failed check under noise would
        # flip it every few cycles: that one waits for the periodic message). No check (a
        # register read holds REG_RD_ADR) raises nothing, as a clean one: not a change, or
        # every ~/read_register would publish the diagnostics twice
        levels += [(bool(f and f.power_failure), bool(f and f.encoder_error))
                   for j in self.joints.values() for f in (j.counters.frame,)]
        levels.extend(int(c.gateway_alive) for c in self.station_clients.values())
        levels.append(int(self.client.gateway_alive) * 2 + int(bool(self._bus_problem())))
        return tuple(levels)

    def _publish_on_change(self) -> None:
        """Publish the diagnostics at once when a level changed since the last cycle."""
        levels = self._levels()
        if self._last_levels and levels != self._last_levels:
            self.publish_diagnostics()
        self._last_levels = levels

    def _statuses(self) -> list:
        s = self.settings
        fqn = self.get_fully_qualified_name()  # type: ignore[attr-defined]
        out = []
        for joint in self.joints.values():
            hw = (f"{s.bus_interface}:{s.bus_channel} node {joint.settings.station or s.node_id} "
                  f"slot {joint.slot} XN-1SSI")
            extra = {"para1": f"0x{joint.para1:08X}",
                     "max_speed": f"{joint.max_speed:g}",
                     "velocity_window": str(s.velocity_window),
                     "stale_limit_cycles": str(s.stale_cycles),
                     "frame_id": s.frame_id}
            st = channel_status(status_name(fqn, joint.name), hw, joint.counters, joint.health,
                                joint.position, extra)
            if joint.para1_note:
                # the likely cause of what a worse level reports (a misread frame's error bits)
                st.message = (joint.para1_note if st.level < WARN
                              else f"{st.message}; {joint.para1_note}")
                st.level = max(st.level, WARN)
            out.append(st)
        if len(self.station_clients) > 1:
            return out + self._station_statuses()
        counters = dataclasses.asdict(self.client.counters)
        counters.update(self.recorder.counters())
        counters["late_frames"] = self.client.table.late_frames
        counters.update(self._cycle_counters())
        meter = getattr(self.client, "load", None)
        if meter is not None:
            counters.update(meter.figures())
        counters.update(self.liveview.counters())
        out.append(self._with_bus_findings(bus_status(
            status_name(fqn, "bus"),
            f"{s.bus_interface}:{s.bus_channel} node {s.node_id} XN-GW-CANOPEN",
            alive=self.client.gateway_alive, connected=self.client.network is not None,
            achieved_rate=self.achieved_rate(), publish_rate=s.publish_rate, counters=counters,
            extra_error=self._bus_problem()), counters))
        return out

    def _cycle_counters(self) -> dict[str, Any]:
        """The bus status's figures of the cycle, its threads and the services (one station
        or several)."""
        counters: dict[str, Any] = {
            "clock_steps": self.clock_steps, "incomplete_cycles": self.incomplete_cycles,
            "samples_set_aside": sum(j.counters.set_aside for j in self.joints.values()),
            "latch_bound_s": f"{self.latch_bound_s:.6f}",
            "cycles_missed": getattr(self.cycle, "missed", 0),
            "cycle_scheduling": getattr(self.cycle, "scheduling", "")}
        if self.master is not None:
            counters["receive_scheduling"] = self.master.receive_scheduling
            counters.update(self.master.link_figures())
            counters.update(self.master.error_frames.figures())
        counters["diagnostics_period_s"] = f"{self.settings.diagnostics_period:g}"
        counters["service_busy_refusals"] = self.handlers.busy_refusals
        counters["service_rested_s"] = f"{self.handlers.queue.rested:.2f}"
        return counters

    def _station_statuses(self) -> list:
        """Several stations: one bus status (master, SYNC, rate) and one per station."""
        s = self.settings
        fqn = self.get_fully_qualified_name()  # type: ignore[attr-defined]
        assert self.master is not None
        counters = dataclasses.asdict(self.master.counters)
        counters.update(self.recorder.counters())
        counters["late_frames"] = sum(c.table.late_frames for c in self.station_clients.values())
        counters.update(self._cycle_counters())
        counters.update(self.master.load.figures())
        silent = [sid for sid, c in self.station_clients.items() if not c.gateway_alive]
        totals = dict(counters)  # each station's supervisor counts into its own client
        for key in ("invalid_nmt_states", "nmt_restarts", BUS_ERROR_COUNT):
            totals[key] = sum(getattr(c.counters, key, 0) for c in self.station_clients.values())
        out = [self._with_bus_findings(bus_status(
            status_name(fqn, "bus"), f"{s.bus_interface}:{s.bus_channel} master of stations "
            f"{list(self.station_clients)}", alive=True, connected=self.master.network is not None,
            achieved_rate=self.achieved_rate(), publish_rate=s.publish_rate, counters=counters,
            extra_error=self._bus_problem()), totals)]
        if silent:
            out[0].values.append(KeyValue(key="silent_stations", value=str(silent)))
        for sid, client in self.station_clients.items():
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

    def _bus_problem(self) -> str:
        """An error beside the bus state: a lost interface, a bus-off controller, the
        recorder's, a simulated station that ended."""
        station = self.station.problem() if self.station is not None else None
        link = self.master.interface_problem() if self.master is not None else ""
        bus_off = self.master.error_frames.problem() if self.master is not None else ""
        return "; ".join(p for p in (link, bus_off, self.recorder.error, self.liveview.error,
                                     station) if p)

    def _on_diag_timer(self) -> None:
        """Periodic diagnostics; the CAM objects are re-read here (SDO, never in the cycle)."""
        lost = self.master is not None and self.master.interface_problem()
        if not self.settings.listen_only and not lost and self.context.ok():  # type: ignore
            self.refresh_cams()  # type: ignore[attr-defined]
        self.publish_diagnostics()

    def publish_diagnostics(self) -> None:
        """Publish one DiagnosticArray with a status per joint and one for the bus."""
        if not self.context.ok():  # type: ignore[attr-defined]
            return
        clock = self.get_clock()  # type: ignore[attr-defined]
        now = clock.now()
        if now.nanoseconds <= 0:
            return  # use_sim_time before the first /clock: no time to stamp with
        msg = DiagnosticArray()
        msg.header.stamp = now.to_msg()
        msg.status = self._statuses()
        if not self.publish_safe(self.diag_pub, msg):  # type: ignore[attr-defined]
            return
        self.recorder.record("/diagnostics", msg, clock.now().nanoseconds)


__all__ = ["NodeDiagnostics"]
