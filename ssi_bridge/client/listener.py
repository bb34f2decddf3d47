"""ListenOnlyClient: a master that only watches the bus another master (or a log) drives.

For debugging a station that a PLC drives, or a recorded CAN log replayed onto a bus, the
bridge must read what is on the wire without touching it: no NMT, no SDO, no SYNC, no RPDO.
The listener assumes the PDO layout the bridge's own master configures (``docs/canopen.md``,
000 Table 15): TPDO s = process input image of slot s (0x2000:s), TPDO 9.. = 0x6820 of slot
pairs, SYNC on 0x080. It fills the same :class:`~ssi_bridge.client.samples.SlotTable` as
:class:`~ssi_bridge.client.master.BridgeClient`, so ``latest(slot)`` gives the same
:class:`~ssi_bridge.client.samples.ChannelSample`, stamped with the observed SYNC's time.

Each observed SYNC opens a cycle; it is reported once through :meth:`next_cycle`, as
complete when every slot's image and position arrived, or as incomplete when the next SYNC
comes first. Times: a frame's python-can timestamp (the time it was on the wire, wire time of
``base/timebase``; a replayed log carries its own) *is* ``ChannelSample.sync_time``: no
clock is read to stamp a cycle.

Liveness: the gateway counts as alive while a heartbeat (0x700 + id) or one of its TPDOs
arrived (frame timestamp) within ``heartbeat_timeout`` of the newest frame handled or of now. Every operation that would send is refused with
:data:`LISTEN_ONLY`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from dataclasses import dataclass

import can

from ssi_bridge.base.rate_log import RateLimitedLog
from ssi_bridge.base.rx_guard import ERROR_PAUSE, RECEIVE_ERROR, receive_error_kind
from ssi_bridge.client.emcy_log import EmcySummary
from ssi_bridge.client.receive import TpdoRoutes
from ssi_bridge.client.samples import ChannelSample, ClientCounters, SlotTable
from ssi_bridge.exceptions import BusError
from ssi_bridge.client.bus import take_bus
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.protocol.dictionary import MAX_SLOTS
from ssi_bridge.protocol.frame_rules import master_rules
from ssi_bridge.base.timebase import frame_wire_time, wire_now

logger = logging.getLogger(__name__)

#: why every sending operation is refused
LISTEN_ONLY = "listen-only: another master drives this bus"
#: CiA 301 COB-IDs the listener watches besides the TPDOs
SYNC_COB_ID = 0x080
EMCY_COB_BASE = 0x080
HEARTBEAT_COB_BASE = 0x700
#: observed cycles kept for :meth:`ListenOnlyClient.next_cycle` (older ones are dropped)
KEEP_CYCLES = 256


@dataclass(frozen=True)
class ObservedCycle:
    """One SYNC seen on the bus and whether every configured slot answered it."""

    #: running number of the SYNC (1 = first observed)
    seq: int
    #: wire time the SYNC was on the wire (its frame timestamp, s): the latch time
    sync_time: float
    #: True when every slot's image and position arrived before the next SYNC
    complete: bool


class ListenOnlyClient(can.Listener):
    """Passive master for a station of ``slots`` XN-1SSI modules behind gateway ``node_id``.

    :param bus: a :class:`BusConfig` (the listener opens its own bus) or an open bus it takes
        over (and shuts down on :meth:`close`)
    :param node_id: the gateway's node id
    :param slots: number of modules (1-8)
    :param heartbeat_timeout: the gateway is silent after this long without its heartbeat
        or a TPDO (s)

    :raises ValueError: ``slots`` outside 1-8
    """

    def __init__(self, bus: BusConfig | can.BusABC, node_id: int, slots: int, *,
                 heartbeat_timeout: float = 0.2) -> None:
        if not 1 <= slots <= MAX_SLOTS:
            raise ValueError(f"slots {slots} outside 1-{MAX_SLOTS}")
        self._source: BusConfig | can.BusABC | None = bus
        self.node_id = node_id
        self.slots = slots
        self.heartbeat_timeout = heartbeat_timeout
        self.counters = ClientCounters()
        self.table = SlotTable(slots)
        #: NMT state of the last heartbeat seen, None before the first
        self.nmt_state: int | None = None
        self._bus: can.BusABC | None = None
        self._notifier: can.Notifier | None = None
        self._routes = TpdoRoutes(node_id, slots, self.table.on_image, self.table.on_positions,
                                  self._on_malformed).routes
        self._heartbeat_id = HEARTBEAT_COB_BASE + node_id
        self._emcy_id = EMCY_COB_BASE + node_id
        #: the heartbeat's and EMCY's lengths (protocol/frame_rules.py): others are malformed
        self._rules = {cob: rule for cob, rule in master_rules(node_id).items()
                       if cob in (self._heartbeat_id, self._emcy_id)}
        self._emcy_log = EmcySummary(logger, f"gateway node {node_id} ")
        self._last_seen = -float("inf")  # wire time of the gateway's last frame (a stamp)
        self._last_seen_at = -float("inf")  # monotonic time it was handled (the interval)
        self._newest = -float("inf")  # newest frame timestamp handled
        self._open: tuple[int, float] | None = None  # (seq, time) of a cycle not yet reported
        self._cycles: deque[ObservedCycle] = deque(maxlen=KEEP_CYCLES)
        self._cycles_cond = threading.Condition()
        self._log = RateLimitedLog(logger)

    def _on_malformed(self, can_id: int, length: int, expected: int) -> None:
        """A TPDO whose length is not its mapping's: counted, not decoded."""
        self.counters.malformed_pdos += 1
        self._log.warning("malformed_pdo", "gateway node %d: TPDO 0x%03X with %d byte(s), "
                           "its mapping has %d: not decoded", self.node_id, can_id, length,
                           expected)

    # -- life cycle -------------------------------------------------------------------------
    def connect(self) -> None:
        """Open the bus and start listening (sends nothing)."""
        if self._bus is not None:
            return
        self._bus = take_bus(self._source, "this listener")
        if not isinstance(self._source, BusConfig):
            self._source = None  # a handed-over bus is taken once
        self._notifier = can.Notifier(self._bus, [self], timeout=0.05)
        logger.info("listening to gateway node %d (%d slot(s)) without driving the bus",
                    self.node_id, self.slots)

    def close(self) -> None:
        """Stop listening and shut the bus down; wakes :meth:`next_cycle` waiters."""
        notifier, self._notifier = self._notifier, None
        if notifier is not None:
            notifier.stop()
        bus, self._bus = self._bus, None
        if bus is not None:
            bus.shutdown()
        with self._cycles_cond:
            self._cycles_cond.notify_all()

    def __enter__(self) -> ListenOnlyClient:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def network(self) -> can.BusABC | None:
        """The bus while listening (None when closed), as ``BridgeClient.network`` is."""
        return self._bus

    # -- observed data ----------------------------------------------------------------------
    def latest(self, slot: int) -> ChannelSample | None:
        """The newest sample of ``slot`` (None before the first complete one)."""
        return self.table.latest(slot)

    def wait_cycle(self, timeout: float) -> bool:
        """True once every slot's image and position arrived since the last observed SYNC.

        :param timeout: longest wait (s); False when it passes first
        """
        return self.table.wait_cycle(timeout)

    def next_cycle(self, timeout: float) -> ObservedCycle | None:
        """The oldest observed cycle not yet returned; None after ``timeout`` s without one."""
        with self._cycles_cond:
            if not self._cycles_cond.wait_for(lambda: self._cycles or self._bus is None,
                                              timeout):
                return None
            return self._cycles.popleft() if self._cycles else None

    @property
    def gateway_alive(self) -> bool:
        """True while a heartbeat or TPDO of the gateway was seen within the timeout.

        The age is monotonic time since the frame was handled (a wall-clock step changes
        nothing); while newer frames handled are not a timeout later on the wire than the
        gateway's last one (frame stamps, one clock), the receive path is behind: alive.
        """
        if self._bus is None:
            return False
        timeout = self.heartbeat_timeout
        return (time.monotonic() - self._last_seen_at <= timeout
                or self._newest - self._last_seen <= timeout)

    # -- refused: a listener never sends -----------------------------------------------------
    def _refuse(self, what: str) -> BusError:
        return BusError(f"{what} refused: {LISTEN_ONLY}")

    def sync(self) -> float:
        """Refused: the other master produces the SYNC.

        :raises BusError: always (listen-only)
        """
        raise self._refuse("SYNC")

    def configure(self) -> None:
        """Refused: the other master configured the gateway.

        :raises BusError: always (listen-only)
        """
        raise self._refuse("gateway configuration")

    def read_register(self, slot: int, addr: int) -> int:
        """Refused: the register handshake writes the process output image.

        Parameters ``slot`` and ``addr`` as :meth:`BridgeClient.read_register`.

        :raises BusError: always (listen-only)
        """
        raise self._refuse(f"slot {slot} register 0x{addr:02X} read handshake")

    def write_register(self, slot: int, addr: int, value: int) -> None:
        """Refused: the register handshake writes the process output image.

        Parameters ``slot``, ``addr``, ``value`` as :meth:`BridgeClient.write_register`.

        :raises BusError: always (listen-only)
        """
        raise self._refuse(f"slot {slot} register 0x{addr:02X} write handshake")

    def set_control(self, slot: int, **bits: bool) -> None:
        """Refused: control bits are part of the process output image.

        Parameters ``slot`` and ``bits`` as :meth:`BridgeClient.set_control`.

        :raises BusError: always (listen-only)
        """
        raise self._refuse(f"slot {slot} control bits")

    def edit_output(self, slot: int, edit: object) -> None:
        """Refused: the process output belongs to the other master.

        Parameters ``slot`` and ``edit`` as :meth:`BridgeClient.edit_output`.

        :raises BusError: always (listen-only)
        """
        raise self._refuse(f"slot {slot} process output")

    def read_object(self, index: int, subindex: int = 0) -> int | float | bytes | str:
        """Refused: an SDO request is a frame on the bus.

        Parameters ``index`` and ``subindex`` as :meth:`BridgeClient.read_object`.

        :raises BusError: always (listen-only)
        """
        raise self._refuse(f"SDO upload of 0x{index:04X}:{subindex:02X}")

    def write_object(self, index: int, subindex: int, value: int | bytes) -> None:
        """Refused: an SDO request is a frame on the bus.

        Parameters ``index``, ``subindex`` and ``value`` as :meth:`BridgeClient.write_object`.

        :raises BusError: always (listen-only)
        """
        raise self._refuse(f"SDO download of 0x{index:04X}:{subindex:02X}")

    # -- notifier thread ----------------------------------------------------------------------
    def on_message_received(self, msg: can.Message) -> None:
        """Dispatch one frame (notifier thread): SYNC, TPDOs, heartbeat, EMCY.

        :param msg: the frame as python-can received it; never raises (a bad frame is counted)
        """
        counters = self.counters
        counters.frames += 1
        wire_t = frame_wire_time(msg)  # between processes: its sender's end of frame
        stamp = wire_t or wire_now()
        if stamp > self._newest:
            self._newest = stamp
        if msg.is_error_frame:
            counters.can_errors += 1
            return
        if msg.is_remote_frame or msg.is_extended_id:
            return
        can_id = msg.arbitration_id
        if can_id == SYNC_COB_ID:
            self._on_sync(wire_t)
            return
        handler = self._routes.get(can_id)
        if handler is not None:
            self._last_seen, self._last_seen_at = stamp, time.monotonic()
            handler(can_id, msg.data, wire_t)
            if self._open is not None and self.table.cycle_complete():
                self._report(*self._open, True)
            return
        rule = self._rules.get(can_id)
        if rule is not None and len(msg.data) != rule.length:
            counters.malformed_frames += 1
            self._log.warning("malformed_frame", "gateway node %d: frame 0x%03X [%s] with %d "
                              "byte(s) is %s: dropped", self.node_id, can_id,
                              bytes(msg.data).hex(" "), len(msg.data),
                              rule.problem(len(msg.data)))
            return
        if can_id == self._heartbeat_id:
            self._last_seen, self._last_seen_at = stamp, time.monotonic()
            self.nmt_state = msg.data[0] & 0x7F
        elif can_id == self._emcy_id:
            counters.emergencies += 1
            self._emcy_log.on_emcy(msg.data[0] | msg.data[1] << 8, bytes(msg.data[3:8]))

    def on_error(self, exc: Exception) -> None:
        """A receive error of the bus (a datagram that is no CAN frame, an interface gone
        down): counted by kind, logged at most once per second, the listener keeps going.

        :param exc: what the bus raised
        """
        kind = receive_error_kind(exc)
        setattr(self.counters, kind, getattr(self.counters, kind) + 1)
        self._log.warning(kind, "listen-only receive error (%s): %s", kind, exc)
        if kind == RECEIVE_ERROR:
            time.sleep(ERROR_PAUSE)

    def _on_sync(self, timestamp: float) -> None:
        if self._open is not None:
            self._report(*self._open, False)
        at = timestamp or wire_now()
        self.counters.syncs += 1
        self._open = (self.table.sync_seq + 1, self.table.on_sync(at))

    def _report(self, seq: int, sync_time: float, complete: bool) -> None:
        self._open = None
        with self._cycles_cond:
            self._cycles.append(ObservedCycle(seq, sync_time, complete))
            self._cycles_cond.notify_all()

