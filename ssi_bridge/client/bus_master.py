"""CanMaster: the one CANopen master of a bus, shared by the clients of several stations.

A CANopen bus has exactly one SYNC producer and one NMT master (CiA 301). The master owns the
bus, canopen's ``Network`` and the SYNC; each station (XN-GW-CANOPEN at its own node id) is
a :class:`~ssi_bridge.client.master.BridgeClient` attached to it with its own RemoteNode, SDO
client, heartbeat consumer, TPDO routes and slot table. :meth:`sync` sends ONE SYNC for all
stations and starts the cycle in every attached client's slot table, so the per-cycle cost
follows the number of slots (one table update per station, no extra frame).
"""

from __future__ import annotations

import threading
import time
from typing import Protocol

import can

from ssi_bridge.client.error_frames import ErrorFrameWatch
from ssi_bridge.client.link import ReopeningBus
from ssi_bridge.client.load import BusLoad
from ssi_bridge.client.receive import FrameListener
from ssi_bridge.client.samples import ClientCounters, CycleGate, SlotTable
from ssi_bridge.exceptions import BusError
from ssi_bridge.client.bus import (
    NOTIFIER_CYCLE, BusOpener, MasterNetwork, ReceiveWatch, open_bus, take_bus,
)
from ssi_bridge.protocol.dictionary import SYNC_COB_ID
from ssi_bridge.protocol.frame_rules import master_rules
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.base.canopen_compat import drop_node
from ssi_bridge.base.timebase import wire_now



class Attached(Protocol):
    """A station's client on the master (``BridgeClient``): its node id, counters, slot table."""

    node_id: int
    counters: ClientCounters
    table: SlotTable

    @property
    def gateway_alive(self) -> bool:
        """True while the station's heartbeat is current."""

    def request_configuration(self) -> None:
        """Have the station configured again by its supervisor thread (the bus came back)."""


class CanMaster:
    """The bus, its canopen network and the single SYNC producer.

    :param bus: a :class:`BusConfig` (the master opens the bus) or an open bus it takes over
    :param counters: where frames, SYNCs and CAN errors of the bus are counted
    :param priority: SCHED_FIFO priority of the receive thread (0: normal scheduling)
    :param opener: opens the bus of a :class:`BusConfig` (default :func:`open_bus`; the node's
        simulation supervisor gives the simulated wire's)
    """

    def __init__(self, bus: BusConfig | can.BusABC,
                 counters: ClientCounters | None = None, priority: int = 0,
                 opener: BusOpener | None = None) -> None:
        self.priority = priority
        self._opener = opener or open_bus
        self._listener: FrameListener | None = None
        self._source: BusConfig | can.BusABC | None = bus
        self.counters = counters if counters is not None else ClientCounters()
        #: bus load from frame timestamps (one bus, so one figure for every station)
        self.load = BusLoad(bus.bitrate if isinstance(bus, BusConfig) else 500_000)
        self.bus: ReceiveWatch | None = None
        #: the opened bus, reopened after its interface is lost (None on a handed-over bus)
        self.link: ReopeningBus | None = None
        self.network: MasterNetwork | None = None
        #: one sender at a time on the network (SYNC, RPDOs of every station)
        self.send_lock = threading.Lock()
        #: one SYNC at a time (the cycle's and a register handshake's own): each one's exact
        #: wire time goes to its own sequence number
        self._sync_lock = threading.Lock()
        self.clients: list[Attached] = []
        #: the stations' slot tables share it: the cycle's waiter wakes once per cycle
        self.gate = CycleGate()
        #: the interface's error frames per class, bus-off and error passive
        self.error_frames = ErrorFrameWatch()
        #: wire time of the latest SYNC of another producer (0.0: none yet)
        self._foreign_sync_at = 0.0
        #: the SYNC frame sent last, sent again while the bus leaves it unstamped (no new
        #: ``can.Message`` each cycle); a simulated wire stamps its frames: a new one each time
        self._sync_frame: can.Message | None = None

    def connect(self) -> None:
        """Open the bus and start canopen's network (idempotent)."""
        if self.network is not None:
            return
        source, opener = self._source, self._opener
        self._sync_frame = None  # made anew by this connection's network
        inner = take_bus(source, "this master", opener)
        if isinstance(source, BusConfig):
            # a lost interface is reopened with back-off (client/link.py)
            self.link = ReopeningBus(inner, lambda: opener(source),
                                     f"{source.interface}:{source.channel}")
            self.link.on_reopen = self._on_reopen
            inner = self.link
        else:
            self._source = None  # a handed-over bus is taken once
        self.bus = ReceiveWatch(inner)
        self.network = MasterNetwork(self.bus, notifier_cycle=NOTIFIER_CYCLE)
        self._listener = FrameListener(self.network, self.counters, self.load, self.priority)
        self._listener.also = [c.counters for c in self.clients if c.counters is not self.counters]
        self._listener.foreign.on_sync = self._on_foreign_sync
        for client in self.clients:
            self._listener.rules.update(master_rules(client.node_id))
        self._listener.error_frames = self.error_frames
        self.network.on_sent = self.load.add
        self.network.start(self._listener)

    @property
    def receive_scheduling(self) -> str:
        """The receive thread's scheduling ("SCHED_FIFO 5", "normal"; "" before a frame)."""
        return self._listener.scheduling if self._listener is not None else ""

    def attach(self, client: Attached) -> None:
        """Register a station's client: its slot table takes part in every SYNC.

        :param client: the station's client (attaching it again changes nothing)
        :raises ValueError: another client with its node id is attached already
        """
        if any(c.node_id == client.node_id for c in self.clients if c is not client):
            raise ValueError(f"node id {client.node_id} already attached to this master")
        if client not in self.clients:
            self.clients.append(client)
        if self._listener is not None:
            self._listener.foreign.watch(client.node_id)
            # heartbeat, EMCY and SDO responses of another length are dropped as malformed
            self._listener.rules.update(master_rules(client.node_id))
        self._count_faults_for(client, True)

    def _count_faults_for(self, client: Attached, on: bool) -> None:
        """Receive faults (undecodable frames, receive and callback errors) of the bus are
        counted in ``client``'s counters too while it is attached (the node publishes them)."""
        if self._listener is None or client.counters is self.counters:
            return
        also = [c for c in self._listener.also if c is not client.counters]
        self._listener.also = also + [client.counters] if on else also

    def detach(self, client: Attached) -> None:
        """Take a station's client off the master (its RemoteNode off the network)."""
        if client in self.clients:
            self.clients.remove(client)
        self._count_faults_for(client, False)
        if self._listener is not None:
            for cob_id in master_rules(client.node_id):
                self._listener.rules.pop(cob_id, None)
        if self.network is not None:
            drop_node(self.network, client.node_id)

    def _on_foreign_sync(self, at: float) -> None:
        """Another producer's SYNC at wire time ``at`` (receive thread): no TPDO after it
        counts for this master's cycle (``client/foreign.py``)."""
        with self.gate.cond:
            self._foreign_sync_at = max(self._foreign_sync_at, at)
            for client in self.clients:
                client.table.on_foreign_sync(at)

    def _on_reopen(self) -> None:
        """The lost interface is open again (receive thread): configure every station."""
        self.error_frames.recovered("the interface was reopened")
        for client in list(self.clients):
            client.request_configuration()

    def interface_problem(self) -> str:
        """The lost interface in words for the bus diagnostics ("" while it works)."""
        return self.link.problem() if self.link is not None else ""

    def link_figures(self) -> dict[str, int]:
        """Losses and reopens of the interface for the bus diagnostics ({} on a handed-over
        bus)."""
        return self.link.figures() if self.link is not None else {}

    def foreign_sync_within(self, window: float) -> bool:
        """Whether another producer's SYNC ended on the wire within the last ``window`` s
        (wire time), cheaply: the diagnostics' change test asks it each cycle. Such a SYNC
        takes the master's cycles (``SlotTable.on_foreign_sync``) and makes the bus WARN."""
        return wire_now() - self._foreign_sync_at <= window

    def foreign_traffic(self, window: float) -> str:
        """SYNC / NMT / SDO request frames of other nodes seen within ``window`` s, in words
        ("" if none), for a WARN of the bus diagnostics."""
        return self._listener.foreign.recent(window) if self._listener is not None else ""

    def sync(self) -> float:
        """Send one SYNC for every station; return its wire time (``base/timebase``).

        On a simulated wire that is the SYNC frame's end-of-frame timestamp, where the modules
        of every station latch; on a real interface the instant it was handed to the driver.

        :returns: the SYNC's wire time (s)
        :raises BusError: the master is not connected, or the SYNC could not be sent while
            the link is not known lost (a cycle with the link lost returns without a SYNC)
        """
        if self.network is None:
            raise BusError("master not connected")
        with self._sync_lock:
            return self._sync()

    def _sync(self) -> float:
        """:meth:`sync` under the SYNC lock."""
        assert self.network is not None
        t = wire_now()
        with self.gate.cond:
            self.gate.open(len(self.clients))
            for client in self.clients:
                client.table.on_sync(t)
        network = self.network
        frame = self._sync_frame  # (a can.Message of no data is falsy: its len is 0)
        if frame is None:
            frame = network.make_frame(SYNC_COB_ID, b"", False)
        try:
            with self.send_lock:
                network.send_frame(frame)
        except can.CanError as err:
            self.counters.can_errors += 1
            if self.link is not None and self.link.lost:
                # a cycle without SYNC: nothing answers, the joints go STALE as under frame
                # loss, and the cycle thread keeps its period (client/link.py reopens)
                return t
            raise BusError(f"could not send SYNC: {err}") from err
        self.counters.syncs += 1
        for client in self.clients:
            if client.counters is not self.counters:
                client.counters.syncs += 1
        if frame.timestamp:  # a bus that stamps what it sent: a new frame next time
            self._sync_frame = None
            with self.gate.cond:
                for client in self.clients:
                    t = client.table.set_sync_time(frame.timestamp)
        else:  # the same frame next cycle (nothing changed it: the bus load measured it)
            self._sync_frame = frame
        return t

    def wait_cycle(self, timeout: float, unanswered_timeout: float = 0.0) -> bool:
        """True once every station's images and positions arrived since the last SYNC.

        Waits ``timeout``; while a station has not answered this SYNC with a single frame (its
        process starved, not its frames lost), up to ``unanswered_timeout`` in all. Frames lost
        on the wire never come, so waiting for them would only delay the next SYNC: the SYNC
        period stays the configured one under frame loss (CiA 301 0x1006 is a period). Nor is
        a station waited for whose gateway is known silent (no heartbeat), nor any once
        another producer's SYNC followed this one: every frame after it answers that SYNC
        (``SlotTable.on_foreign_sync``), so none can complete this cycle. The other stations'
        cycles keep their period.
        """
        start = time.monotonic()
        gate = self.gate
        with gate.cond:  # one hold of the lock for the wait and the checks (it is re-entrant)
            if gate.wait(timeout):
                return True
            if all(client.table.answering or not client.gateway_alive
                   or self._foreign_sync_at > client.table.sync_time
                   for client in self.clients):
                return False
            left = unanswered_timeout - (time.monotonic() - start)
            return left > 0 and gate.wait(left)

    def wait_claim(self, timeout: float, unanswered_timeout: float = 0.0) -> bool:
        """:meth:`wait_cycle`, then ``CycleGate.claim`` of the cycle armed for it, under one
        hold of the gate's lock: True when the caller runs the cycle itself (no frame took it),
        False once the receive thread has run it (raises what :meth:`wait_cycle` raises, the
        cycle claimed all the same).

        :param timeout: the wait for the cycle (s), as :meth:`wait_cycle` takes it
        :param unanswered_timeout: the longest wait (s) while a station answered nothing
        """
        gate = self.gate
        with gate.cond:
            try:
                self.wait_cycle(timeout, unanswered_timeout)
            finally:
                mine = gate.claim()
        return mine

    def send(self, cob_id: int, data: bytes) -> None:
        """Send one frame under the send lock.

        :param cob_id: the frame's CAN identifier (11 bit)
        :param data: its payload (0-8 bytes)
        :raises BusError: the master is not connected
        :raises can.CanError: the bus refused the frame
        """
        if self.network is None:
            raise BusError("master not connected")
        with self.send_lock:
            self.network.send_message(cob_id, data)

    def close(self) -> None:
        """Shut the bus down (the gateways keep running)."""
        if self.network is not None:
            network, self.network = self.network, None
            network.disconnect()
        self.bus = None
