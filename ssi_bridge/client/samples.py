"""What the master keeps per slot: latest sample, process images, counters, freshness.

:class:`SlotTable` is filled by TPDO callbacks on the network thread and read by the timer
thread (``latest``/``wait_cycle``) and the service thread (handshake); one condition
variable guards it. A sample is attributed to the last SYNC sent before it arrived.
"""

from __future__ import annotations

import struct
import threading
import time
from dataclasses import dataclass, field

from ssi_bridge.module.images import ProcessInput

#: two Integer32 positions in one encoder default PDO (000 Table 15, object 0x6820)
POSITION_PAIR = struct.Struct("<ii")
#: SYNC times remembered to stamp late samples
_KEEP_SYNC_TIMES = 64


@dataclass(frozen=True)
class ChannelSample:
    """The newest data of one slot, as the ROS node publishes it."""

    #: slot number 1..8 (object subindex)
    slot: int
    #: REG_SSI_POS as Integer32 (object 0x6820)
    position: int
    #: the 8-byte process input image (000 "Process input")
    process_input: bytes
    #: time.monotonic() of the SYNC that produced this sample (s)
    sync_time: float
    #: number of process input images received for this slot
    counter: int


@dataclass
class ClientCounters:
    """Health counters of the master (for /diagnostics)."""

    #: CAN frames received
    frames: int = 0
    #: CAN error frames received or send failures
    can_errors: int = 0
    #: register handshakes that failed (refusal, timeout, silent gateway)
    handshake_failures: int = 0
    #: handshake steps or SDO transfers that timed out
    timeouts: int = 0
    #: SYNC frames sent
    syncs: int = 0
    #: times the gateway was (re)configured
    configurations: int = 0
    #: boot-up messages seen (gateway restarts)
    restarts: int = 0
    #: EMCY frames received
    emergencies: int = 0


@dataclass
class _Slot:
    image: bytes | None = None
    image_seq: int = -1
    image_count: int = 0
    position: int | None = None
    position_seq: int = -1
    output: bytearray = field(default_factory=lambda: bytearray(8))
    edit_seq: int = 0  # sync sequence at the last output edit
    pulse_seq: int | None = None  # clear pulse armed at this sync sequence


class CycleGate:
    """One condition and one wake-up per cycle for the slot tables of several stations.

    The master sets ``pending`` to the number of stations at each SYNC; a table whose cycle
    completes counts it down, and only the last one wakes the cycle's waiter, so the cycle
    thread is woken once per cycle however many stations answer.
    """

    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.pending = 0

    def open(self, stations: int) -> None:
        """A SYNC for ``stations`` tables is about to go out (call under :attr:`cond`)."""
        self.pending = stations

    def wait(self, timeout: float) -> bool:
        """Wait until every station's cycle is complete or ``timeout`` (s) elapses."""
        with self.cond:
            return self.cond.wait_for(lambda: self.pending <= 0, timeout)


class SlotTable:
    """Per-slot state shared by the network, timer and service threads.

    The waiters are woken once per cycle, not per frame: ``_due`` counts the images and
    positions not yet received for the current SYNC (``image_seq``/``position_seq`` behind
    ``sync_seq``), so :meth:`cycle_complete` is ``_due == 0`` and a frame notifies only when
    it completes the cycle or a handshake waits in :meth:`next_input`.
    """

    def __init__(self, slots: int, gate: CycleGate | None = None) -> None:
        self.slots = slots
        #: shared with the other stations' tables of one master (one wake-up per cycle)
        self._gate = gate
        self.cond = gate.cond if gate is not None else threading.Condition()
        self.sync_seq = 0
        self.sync_time = 0.0
        self.last_sync_monotonic = 0.0
        self._slots = {s: _Slot() for s in range(1, slots + 1)}
        self._times: dict[int, float] = {}
        self._due = 2 * slots
        self._input_waiters = 0

    def slot(self, slot: int) -> _Slot:
        """The state of ``slot`` (raises KeyError with the valid range)."""
        try:
            return self._slots[slot]
        except KeyError:
            raise KeyError(f"slot {slot} not configured (1..{self.slots})") from None

    def on_sync(self, at: float | None = None) -> float:
        """Record a SYNC about to be sent (or, with ``at``, one observed then); return its time.

        ``at`` is a ``time.monotonic()`` instant: a listen-only master stamps the cycle with
        the time the SYNC of another master was on the wire, not with when it handled it.
        """
        with self.cond:
            self.sync_seq += 1
            self._due = 2 * self.slots
            self.sync_time = self.last_sync_monotonic = time.monotonic() if at is None else at
            self._times[self.sync_seq] = self.sync_time
            self._times.pop(self.sync_seq - _KEEP_SYNC_TIMES, None)
            return self.sync_time

    def on_image(self, slot: int, data: bytes) -> _Slot:
        """Store a received process input image; return the slot's state."""
        with self.cond:
            st = self._slots[slot]
            completed = False
            if st.image_seq != self.sync_seq:
                st.image_seq = self.sync_seq
                self._due -= 1
                completed = self._due == 0
            st.image = data if type(data) is bytes else bytes(data)
            st.image_count += 1
            if self._completes(completed) or self._input_waiters:
                self.cond.notify_all()
            return st

    def on_positions(self, slots: list[int], data: bytes) -> None:
        """Store the positions of an encoder default PDO."""
        if len(data) == POSITION_PAIR.size:
            values = POSITION_PAIR.unpack(data)
        else:
            values = POSITION_PAIR.unpack(bytes(data).ljust(POSITION_PAIR.size, b"\0"))
        with self.cond:
            seq = self.sync_seq
            completed = False
            for slot, value in zip(slots, values):
                st = self._slots[slot]
                if st.position_seq != seq:
                    st.position_seq = seq
                    self._due -= 1
                    completed = completed or self._due == 0
                st.position = value
            if self._completes(completed):
                self.cond.notify_all()

    def _completes(self, completed: bool) -> bool:
        """Whether to wake the waiters: this frame completed the cycle (of every station)."""
        if self._gate is None:
            return self._due == 0
        if not completed:
            return False
        self._gate.pending -= 1
        return self._gate.pending <= 0

    def latest(self, slot: int) -> ChannelSample | None:
        """The newest complete sample of ``slot`` or None before the first one."""
        with self.cond:
            st = self.slot(slot)
            if st.image is None or st.position is None:
                return None
            return ChannelSample(slot, st.position, st.image,
                                 self._times.get(st.image_seq, 0.0), st.image_count)

    def cycle_complete(self) -> bool:
        """True when every slot's image and position arrived since the last SYNC."""
        return self._due == 0

    def wait_cycle(self, timeout: float) -> bool:
        """Wait until :meth:`cycle_complete` or ``timeout`` (s) elapses."""
        with self.cond:
            return self.cond.wait_for(self.cycle_complete, timeout)

    def next_input(self, slot: int, timeout: float) -> ProcessInput | None:
        """Wait for an image newer than the slot's last output edit."""
        with self.cond:
            st = self._slots[slot]
            self._input_waiters += 1
            try:
                fresh = self.cond.wait_for(lambda: st.image_seq > st.edit_seq, timeout)
            finally:
                self._input_waiters -= 1
            if fresh:
                assert st.image is not None
                return ProcessInput.decode(st.image)
            return None
