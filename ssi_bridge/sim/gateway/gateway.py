"""XN-GW-CANOPEN station model: a canopen ``LocalNode`` serving 1-8 XN-1SSI modules.

Wiring only; the pieces live next door: ``dictionary`` (Table 16 OD), ``objects`` (OD <->
module), ``pdo`` (PDO engine), ``emergency`` (EMCY / 0x1001 / 0x1003), ``bus`` (bus + fault
wrapper). Behaviour (000 chapter 4, CiA 301):

* boot-up message then PRE-OPERATIONAL on start, after NMT "reset node" / "reset
  communication" and after :meth:`XnGateway.restart` (a simulated power cycle);
* SDO served in PRE-OPERATIONAL and OPERATIONAL, not in STOPPED;
* on each SYNC (COB-ID from 0x1005) in PRE-OPERATIONAL/OPERATIONAL every module runs one
  cycle at ``clock()``; EMCYs follow the diagnostics edges; in OPERATIONAL the synchronous
  RPDOs are applied first and the due TPDOs are sent after the cycle;
* heartbeat producer per 0x1017 (canopen's ``NmtSlave``);
* ``silent = True`` mutes everything the station sends (fault "gateway silent");
* frames reach it through its CAN controller's receive FIFO (``controller.py``): a few frames
  deep, a stalled gateway loses the rest (EMCY 0x8110 once per overrun episode) and latches a
  SYNC when it handles it; ``queue_backlog = True`` keeps every frame instead (fault
  QUEUE_BACKLOG: every queued SYNC answered, latched at its own wire time).

All bus callbacks run on the network's notifier thread and take the gateway lock, so the
modules are only ever touched by one thread at a time.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import can
import canopen
from canopen import SdoAbortedError
from canopen.objectdictionary import ODArray, ODVariable

from ssi_bridge.exceptions import BusError
from ssi_bridge.protocol.aborts import SdoAbort
from ssi_bridge.base.canopen_compat import forget_values
from ssi_bridge.base.rx_guard import GuardedListener
from ssi_bridge.protocol.frame_rules import station_rules
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import NOTIFIER_CYCLE, BridgeNetwork, LossyBus, take_bus
from ssi_bridge.sim.gateway.controller import ControllerListener, RxFifo, grace_for
from ssi_bridge.base.od import build_dictionary
from ssi_bridge.sim.gateway.emergency import Emergencies
from ssi_bridge.sim.gateway.objects import EncoderObjects
from ssi_bridge.sim.gateway.pdo import PdoEngine
from ssi_bridge.sim.gateway.sdo_server import StationSdo
from ssi_bridge.base.timebase import ModelClock

if TYPE_CHECKING:
    from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

logger = logging.getLogger(__name__)

NMT_CMD_RESET_NODE = 0x81
NMT_CMD_RESET_COMM = 0x82
NMT_CMD_PRE_OPERATIONAL = 0x80
SYNC_COB_OBJECT = 0x1005
_SDO_STATES = ("PRE-OPERATIONAL", "OPERATIONAL")
#: rest (s) after a cycle's last SSI clock burst before the next cycle may latch: longer than
#: any encoder's monoflop time (15-25 us SICK, 004 §2.2; 9-41 us TR, 001 §5.2.3; 150 us ATM60),
#: so SYNCs a stalled gateway handles back to back read the line one after the other, as one
#: firmware does, instead of clocking an encoder that still holds its line low. SYNCs on time
#: are further apart (1 ms at 1 kHz) and latch at their wire time, untouched
SSI_REST_S = 200e-6


class _StationNode(canopen.LocalNode):
    """A LocalNode that reports every completed SDO/PDO write (to re-read PDO parameters)."""

    #: the station's SDO server (canopen's ``SdoServer`` with the refused-frame report)
    sdo: StationSdo

    def __init__(self, node_id: int, od: canopen.ObjectDictionary,
                 after_write: Callable[[int, int], None], lock: threading.RLock) -> None:
        super().__init__(node_id, od)
        self._after_write = after_write
        self.lock = lock
        self.sdo = StationSdo(self, _SDO_STATES)

    def set_data(self, index: int, subindex: int, data: bytes,
                 check_writable: bool = False) -> None:
        super().set_data(index, subindex, data, check_writable)
        self._after_write(index, subindex)


class XnGateway:
    """The station: ``start()`` it on a bus, drive it with SYNC from a master, ``stop()`` it.

    :param bus: a :class:`BusConfig` (the gateway opens and closes its own bus) or an open
        python-can bus (the gateway takes it over and shuts it down in :meth:`stop`)
    :param node_id: CANopen node id 1-127
    :param modules: the XN-1SSI modules in slots 1..n (1-8)
    :param clock: the station's model clock (wire time minus its start, ``base/timebase``):
        a SYNC latches the modules at ``clock.at(frame timestamp)``
    :raises ValueError: ``node_id`` outside 1-127
    """

    def __init__(self, bus: BusConfig | can.BusABC, node_id: int, modules: Sequence[Xn1Ssi],
                 *, clock: ModelClock | None = None) -> None:
        if not 1 <= node_id <= 127:
            raise ValueError(f"node id {node_id} outside 1-127")
        self._source: BusConfig | can.BusABC | None = bus
        self.node_id = node_id
        self.modules = list(modules)
        self.clock = clock if clock is not None else ModelClock()
        self.od = build_dictionary(node_id, len(self.modules))
        self.objects = EncoderObjects(self.modules)
        self.emergencies = Emergencies(len(self.modules), self._send_emcy)
        self._lock = threading.RLock()
        self.node = _StationNode(node_id, self.od, self._after_write, self._lock)
        self.node.add_read_callback(self._check_subindex)
        self.node.add_read_callback(self.emergencies.on_read)
        self.node.add_read_callback(self.objects.on_read)
        self.node.add_write_callback(self._check_subindex)
        self.node.add_write_callback(self._check_write)
        self.node.add_write_callback(self.emergencies.on_write)
        self.node.add_write_callback(self.objects.on_write)
        self.pdo = PdoEngine(self.node, self._send_frames, self.objects.pdo_reader,
                             self.objects.pdo_packer, lock=self._lock)
        self.bus: LossyBus | None = None
        self.network: BridgeNetwork | None = None
        self.listener: GuardedListener | None = None
        self._sync_cob: int | None = None
        self._answering: float | None = None  # wire time of the SYNC being answered
        #: the CAN controller's receive FIFO (frames lost to overruns, late handling)
        self.rx_fifo = RxFifo()
        #: the FIFO's handling grace (s) from :meth:`start` on; None: by the bus
        #: (``controller.grace_for``: unbounded in-process, 20 ms for a station process)
        self.stall_grace: float | None = None
        #: SCHED_FIFO priority of the receive thread from :meth:`start` on (0: none); the
        #: node's in-process station gets ``simulation.station_priority``
        self.rx_priority = 0
        #: SYNC cycles run so far
        self.cycles = 0
        # model time before which no new cycle latches: the last SSI reads and their rest
        self._next_latch = -float("inf")

    # -- life cycle -------------------------------------------------------------------------
    def start(self) -> None:
        """Open the bus, join the network and boot (boot-up message, PRE-OPERATIONAL)."""
        if self.network is not None:
            return
        inner = take_bus(self._source, "this gateway")
        if not isinstance(self._source, BusConfig):
            self._source = None  # a handed-over bus is taken once
        self.rx_fifo.grace = grace_for(inner) if self.stall_grace is None else self.stall_grace
        self.bus = LossyBus(inner)
        self.network = BridgeNetwork(self.bus, notifier_cycle=NOTIFIER_CYCLE)
        # subscribers get each frame's handling time through the controller's receive FIFO
        # (a SYNC latches then) and no undecodable datagram, receive error or raising
        # callback stops the station
        listener = ControllerListener(self.network, f"gateway node {self.node_id}",
                                      self.rx_fifo, self._on_overrun,
                                      priority=self.rx_priority)
        # an NMT command or SDO request of another length, or an SDO segment outside a
        # transfer, is counted and logged as malformed, never decoded (protocol/frame_rules)
        listener.rules.update(station_rules(self.node_id))
        self.node.sdo.report = listener.malformed
        #: the station's receive path: its faults by kind (``listener.faults``)
        self.listener = listener
        self.network.start(listener)
        self.network.add_node(self.node)
        self.network.subscribe(0, self._on_nmt)
        with self._lock:
            self._boot(reset_application=False)
        logger.info("gateway node %d up with %d module(s)", self.node_id, len(self.modules))

    def stop(self) -> None:
        """Stop heartbeat and PDOs and shut the bus down (idempotent)."""
        if self.network is None:
            return
        with self._lock:
            self.node.nmt.stop_heartbeat()
            self.pdo.detach()
            network, self.network = self.network, None
            network.unsubscribe(0, self._on_nmt)
            del network[self.node_id]
            self._sync_cob = None
        network.disconnect()
        self.bus = None
        fifo = self.rx_fifo
        logger.info("gateway node %d stopped; receive FIFO: %d frame(s) lost in %d overrun(s), "
                    "%d taken after a stall, longest delay %.1f ms", self.node_id, fifo.lost,
                    fifo.overruns, fifo.late, fifo.worst_delay * 1000.0)

    def __enter__(self) -> XnGateway:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def restart(self) -> None:
        """Simulate a power cycle: forget all SDO-written data, boot-up, PRE-OPERATIONAL."""
        with self._lock:
            self._boot(reset_application=True)

    @property
    def silent(self) -> bool:
        """True while the station sends nothing at all (fault injection)."""
        return self.bus is not None and self.bus.muted

    @silent.setter
    def silent(self, value: bool) -> None:
        if self.bus is None:
            raise BusError("gateway not started")
        self.bus.muted = bool(value)

    @property
    def queue_backlog(self) -> bool:
        """True while the gateway queues every received frame and answers every SYNC
        (fault QUEUE_BACKLOG) instead of holding what its controller's FIFO holds."""
        return self.rx_fifo.queueing

    @queue_backlog.setter
    def queue_backlog(self, value: bool) -> None:
        with self._lock:
            self.rx_fifo.set_queueing(value)

    @property
    def nmt_state(self) -> str:
        """The NMT state as canopen names it ("PRE-OPERATIONAL", "OPERATIONAL", ...)."""
        return self.node.nmt.state

    # -- internals ---------------------------------------------------------------------------
    def _boot(self, *, reset_application: bool) -> None:
        self.node.nmt.stop_heartbeat()
        if reset_application:
            forget_values(self.node)
            self.objects.reset()
            self.emergencies.reset()
        else:
            forget_values(self.node, lambda index: 0x1000 <= index < 0x2000)
        self.pdo.reload()
        self._subscribe_sync()
        self.node.nmt.send_command(NMT_CMD_RESET_NODE)  # INITIALISING: boot-up message
        self.node.nmt.send_command(NMT_CMD_PRE_OPERATIONAL)  # starts heartbeat per 0x1017

    def _subscribe_sync(self) -> None:
        assert self.network is not None
        entry = self.od[SYNC_COB_OBJECT]
        assert isinstance(entry, ODVariable)  # COB-ID SYNC: a VAR, UNSIGNED32 (CiA 301)
        raw = entry.decode_raw(self.node.get_data(SYNC_COB_OBJECT, 0))
        assert isinstance(raw, int)
        cob = raw & 0x7FF
        if cob != self._sync_cob:
            if self._sync_cob is not None:
                self.network.unsubscribe(self._sync_cob, self._on_sync)
            self.network.subscribe(cob, self._on_sync)
            self._sync_cob = cob

    def _check_subindex(self, index: int, subindex: int, od: object, **_: object) -> None:
        # canopen's ODArray invents any subindex 1-255 on lookup; the station has one per slot
        entry = self.od[index]
        if isinstance(entry, ODArray) and subindex not in entry.subindices:
            raise SdoAbortedError(SdoAbort.NO_SUCH_SUBINDEX)

    def _check_write(self, index: int, subindex: int, od: object, data: bytes) -> None:
        if 0x1400 <= index < 0x1C00:
            self.pdo.check_write(index, subindex, data)

    def _after_write(self, index: int, subindex: int) -> None:
        if 0x1400 <= index < 0x1C00:
            self.pdo.reload()
        elif index == SYNC_COB_OBJECT:
            self._subscribe_sync()

    def _send_frames(self, frames: list[tuple[int, bytes]]) -> None:
        """Send one SYNC cycle's TPDOs (a frame the bus refuses is logged, the rest go)."""
        if self.network is None:
            return
        for cob_id, err in self.network.send_messages(frames, self._answering):
            logger.warning("gateway could not send 0x%03X: %s", cob_id, err)

    def _send_emcy(self, code: int, register: int, data: bytes) -> None:
        if self.network is not None:
            try:
                self.node.emcy.send(code, register, data)
            except can.CanError as err:
                logger.warning("gateway could not send EMCY: %s", err)

    def _on_overrun(self, lost: int) -> None:
        """The controller's FIFO lost a frame, the first of an overrun episode (receive
        thread): EMCY 0x8110 where the NMT state allows EMCY (CiA 301: not in STOPPED)."""
        logger.warning("gateway node %d: CAN overrun, frames lost (%d so far)", self.node_id,
                       lost)
        with self._lock:
            self.emergencies.overrun(lost, may_send=self.node.nmt.state in _SDO_STATES)

    def _on_nmt(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if len(data) < 2 or data[1] not in (0, self.node_id):
            return
        if data[0] in (NMT_CMD_RESET_NODE, NMT_CMD_RESET_COMM):
            logger.info("gateway node %d: NMT reset (0x%02X)", self.node_id, data[0])
            with self._lock:
                self._boot(reset_application=data[0] == NMT_CMD_RESET_NODE)

    def _acquisition_time(self, timestamp: float) -> float:
        """Model time at which the gateway handles the SYNC: every module latches then.

        A real gateway latches its modules when its firmware handles the SYNC. ``timestamp``
        is that instant as the controller model gives it (``controller.py``): the SYNC's wire
        time when the station's thread got to it within the grace (on udp_multicast the
        sender's end of frame, not the receive time, which is late by however long the
        sender slept past it), the wire time at which the thread handled it after a stall,
        and under QUEUE_BACKLOG always the SYNC's wire time. The latch is that instant in the
        model clock: one subtraction of a constant, no clock read here. (It used to read the
        model clock and ``time.time()`` in two statements: a thread switch between them moved
        the latch back by the switch, into the previous burst's monoflop time, and the module
        saw a line held low: a false ERR_SSI.) Without a timestamp: now.
        """
        return self.clock.at(timestamp) if timestamp else self.clock()

    def _await_readout(self, end: float) -> None:
        """Wait until model time ``end``, the end of this cycle's SSI reads: the TPDOs carry
        their result, so a firmware sends them after it, never before. A latch is later than
        its SYNC's handling time when SYNCs come faster than the reads (handled back to back:
        ``_next_latch``); answering such a SYNC at once would put on the wire, ahead of its
        own instant, a position the shaft reaches only later."""
        wait = end - self.clock()
        if wait > 0:
            time.sleep(wait)

    def _on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        with self._lock:
            state = self.node.nmt.state
            if state not in _SDO_STATES:
                return
            operational = state == "OPERATIONAL"
            if operational:
                self.pdo.apply_pending()
            t = self._acquisition_time(timestamp)
            if t < self._next_latch:
                t = self._next_latch  # the previous cycle's SSI reads still run
            try:
                self.objects.cycle(t)
            except Exception:  # a module bug must not kill the notifier thread
                logger.exception("module cycle failed")
            self._next_latch = max((r.end_time for m in self.modules
                                    if (r := m.last_readout) is not None), default=t) + SSI_REST_S
            self.cycles += 1
            if operational:
                self._await_readout(self._next_latch - SSI_REST_S)
            emergencies = self.emergencies
            if emergencies.overrun_active:
                emergencies.overrun_over(may_send=True)  # the FIFO took this SYNC
            emergencies.update([m.diag for m in self.modules], may_send=True)
            if operational:
                # synchronous TPDOs answer this SYNC only: not once a newer one is on the
                # wire; a queueing device answers every SYNC it queued, however late
                self._answering = None if self.rx_fifo.queueing else (timestamp or None)
                try:
                    self.pdo.on_sync()
                finally:
                    self._answering = None
