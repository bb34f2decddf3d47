"""What the master keeps per slot: latest sample, process images, counters, freshness.

:class:`SlotTable` is filled by TPDO callbacks on the network thread and read by the timer
thread (``latest``/``wait_cycle``) and the service thread (handshake); one condition
variable guards it. A sample is attributed to the last SYNC sent before it arrived.
"""

from __future__ import annotations

import struct
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from ssi_bridge.base.timebase import wire_now
from ssi_bridge.client.cycle_gate import CycleGate as CycleGate
from ssi_bridge.client.frame_sink import FrameSink
from ssi_bridge.protocol.images import ProcessInput

#: two Integer32 positions in one encoder default PDO (000 Table 15, object 0x6820)
POSITION_PAIR = struct.Struct("<ii")
#: SYNC times remembered to stamp late samples
_KEEP_SYNC_TIMES = 64


def _WAKE() -> None:
    """What ``SlotTable._completes`` returns for "wake the waiters" (never run)."""


@dataclass(frozen=True)
class ChannelSample:
    """The newest data of one slot, as the ROS node publishes it."""

    #: slot number 1..8 (object subindex)
    slot: int
    #: REG_SSI_POS as Integer32 (object 0x6820)
    position: int
    #: the 8-byte process input image (000 "Process input")
    process_input: bytes
    #: wire time (``base/timebase``) of the SYNC that produced this sample (s)
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
    #: clear pulses (CLR_CMPx) sent again because the image showed they never arrived
    pulse_resends: int = 0
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
    #: received datagrams that were not CAN frames (udp_multicast), dropped
    undecodable_frames: int = 0
    #: TPDOs on the master's COB-IDs whose length differs from their mapping, not decoded
    malformed_pdos: int = 0
    #: frames on a station's heartbeat, EMCY or SDO response COB-ID whose length CiA 301 does
    #: not give that service (``protocol/frame_rules.py``), not decoded
    malformed_frames: int = 0
    #: errors of the bus's receive call (the receive path went on)
    receive_errors: int = 0
    #: exceptions raised by a handler of a received frame (the receive path went on)
    callback_errors: int = 0
    #: heartbeats whose NMT state is none of CiA 301's (0, 4, 5, 127), ignored
    invalid_nmt_states: int = 0
    #: stations found STOPPED or PRE-OPERATIONAL by heartbeat and started again
    nmt_restarts: int = 0
    #: rounds of the supervisor thread that raised an unexpected exception (it went on)
    supervisor_errors: int = 0
    #: SYNC frames of another producer received (CiA 301: one per network)
    foreign_syncs: int = 0
    #: TPDOs not taken for the master's cycle: they followed another producer's SYNC
    foreign_sync_answers: int = 0
    #: NMT commands received that this master did not send
    foreign_nmt_commands: int = 0
    #: SDO requests to this master's stations that it did not send
    foreign_station_frames: int = 0
    #: SDO server frames that answered no current request (a late answer to an earlier,
    #: timed-out request, a repeated answer), set aside (``client/sdo_answers.py``)
    stale_sdo_answers: int = 0


@dataclass
class SlotState:
    """One slot's newest image and position, its output image and clear-pulse state."""

    image: bytes | None = None
    image_seq: int = -1
    image_time: float = 0.0  # wire time (frame timestamp) of the image
    image_count: int = 0
    position: int | None = None
    position_seq: int = -1
    position_time: float = 0.0
    output: bytearray = field(default_factory=lambda: bytearray(8))
    edit_seq: int = 0  # sync sequence at the last output edit
    pulse_seq: int | None = None  # clear pulse armed at this sync sequence
    pulse_resends: int = 0  # times the current clear pulse was sent again (lost RPDO)
    release_seq: int | None = None  # CLR released at this sync sequence: sent once more


class SlotTable:
    """Per-slot state shared by the network, timer and service threads.

    The waiters are woken once per cycle, not per frame: ``_due`` counts the images and
    positions not yet received for the current SYNC (``image_seq``/``position_seq`` behind
    ``sync_seq``), so :meth:`cycle_complete` is ``_due == 0`` and a frame notifies only when
    it completes the cycle or a handshake waits in :meth:`next_input`. A frame completing a
    cycle the cycle thread armed on the gate (``client/cycle_gate.py``) runs that cycle on its
    own thread, out of the lock, and the waiters are woken once it ended.

    :param slots: modules in the station (slots 1..slots)
    :param gate: the master's cycle gate shared with the other stations' tables (None: a
        condition of this table's own)
    """

    def __init__(self, slots: int, gate: CycleGate | None = None) -> None:
        self.slots = slots
        #: shared with the other stations' tables of one master (one wake-up per cycle)
        self._gate = gate
        self.cond = gate.cond if gate is not None else threading.Condition()
        self.sync_seq = 0
        self.sync_time = 0.0
        #: monotonic time of the last SYNC recorded (an interval's start, never a stamp)
        self.synced_at = float("-inf")
        self._slots = {s: SlotState() for s in range(1, slots + 1)}
        self._times: dict[int, float] = {}
        self._due = 2 * slots
        self._input_waiters = 0
        #: TPDOs that answered an older SYNC than the current one (not counted for it)
        self.late_frames = 0
        #: wire time of the first SYNC of another producer after the current SYNC, or None
        self._foreign_since: float | None = None
        #: TPDOs that followed another producer's SYNC (not taken at all)
        self.foreign_answers = 0
        #: where ``foreign_sync_answers`` is counted too (the station's client), or None
        self.counters: ClientCounters | None = None
        #: the cycle's frame log: every SYNC and TPDO with its wire time, or None
        self.sink: FrameSink | None = None

    @property
    def cond(self) -> threading.Condition:
        """The condition guarding the table (the gate's, shared by a master's stations)."""
        return self._cond

    @cond.setter
    def cond(self, cond: threading.Condition) -> None:
        self._cond = cond
        # its lock, taken and released by its own (C) methods on the hot path
        self._acquire, self._release = cond.acquire, cond.release

    def slot(self, slot: int) -> SlotState:
        """The state of ``slot`` (raises KeyError with the valid range)."""
        try:
            return self._slots[slot]
        except KeyError:
            raise KeyError(f"slot {slot} not configured (1..{self.slots})") from None

    def on_sync(self, at: float | None = None) -> float:
        """Record a SYNC about to be sent (or, with ``at``, one observed then); return its time.

        ``at`` is a wire time: a listen-only master stamps the cycle with the time the SYNC
        of another master was on the wire (its frame timestamp), not with when it handled it.
        """
        with self.cond:
            self.sync_seq += 1
            self._foreign_since = None
            self._due = 2 * self.slots
            self.sync_time = wire_now() if at is None else at
            self.synced_at = time.monotonic()
            self._times[self.sync_seq] = self.sync_time
            self._times.pop(self.sync_seq - _KEEP_SYNC_TIMES, None)
            if self.sink is not None:
                self.sink.sync(self.sync_seq, self.sync_time)
            return self.sync_time

    def set_sync_time(self, at: float) -> float:
        """The current SYNC's wire time, once the wire has given it (its end of frame).

        A TPDO handled meanwhile that ended on the wire before this SYNC answered the one
        before: it no longer counts for this cycle.

        :param at: the SYNC's end-of-frame wire time (s)
        :returns: the SYNC time the table now holds (``at``)
        """
        with self.cond:
            self.sync_time = at
            if self._foreign_since is not None and self._foreign_since <= at:
                self._foreign_since = None  # it was on the wire before this SYNC, not after
            seq = self.sync_seq
            self._times[seq] = at
            if self.sink is not None:
                self.sink.sync(seq, at)
            was_complete = self._due == 0
            for st in self._slots.values():
                if st.image_seq == seq and 0.0 < st.image_time < at:
                    st.image_seq = seq - 1
                    self._due += 1
                if st.position_seq == seq and 0.0 < st.position_time < at:
                    st.position_seq = seq - 1
                    self._due += 1
            if was_complete and self._due and self._gate is not None:
                self._gate.pending += 1  # counted as complete too early: not any more
            return at

    def on_foreign_sync(self, at: float) -> None:
        """Another producer's SYNC ended on the wire at ``at`` (call under :attr:`cond`): a
        TPDO after it answers that SYNC, latched then, and is not taken for this cycle."""
        if self.sink is not None:
            self.sink.foreign_sync(at)
        if at > self.sync_time and (self._foreign_since is None or at < self._foreign_since):
            self._foreign_since = at

    def _count_foreign(self) -> None:
        """A TPDO that followed another producer's SYNC (after ``_foreign_since``): counted,
        not taken."""
        self.foreign_answers += 1
        if self.counters is not None:
            self.counters.foreign_sync_answers += 1

    def on_image(self, slot: int, data: bytes | bytearray, timestamp: float = 0.0) -> SlotState:
        """Store a received process input image (wire time ``timestamp``); return the slot.

        A SYNC's TPDOs follow it on the wire, so an image that ended before the current
        SYNC belongs to an older cycle: kept as the newest image, not counted for this one.

        :param slot: the module's slot (1-based; TPDO ``slot`` carries it)
        :param data: the 8-byte process input image
        :returns: the slot's state after storing it
        """
        job: Callable[[], None] | None = None
        self._acquire()  # the lock of :attr:`cond` (its C methods: every TPDO comes here)
        try:
            st = self._slots[slot]
            image = data if type(data) is bytes else bytes(data)  # one copy, kept by both
            if self.sink is not None:
                self.sink.image(slot, timestamp, image, st.image_count + 1)
            since = self._foreign_since
            if since is not None and timestamp > since:  # _foreign, inline
                self._count_foreign()
                return st
            completed = False
            if 0.0 < timestamp < self.sync_time:  # _late, inline
                self.late_frames += 1
                st.image_seq = max(st.image_seq, self.sync_seq - 1)
            elif st.image_seq != self.sync_seq:
                st.image_seq = self.sync_seq
                self._due -= 1
                completed = self._due == 0
            st.image = image
            st.image_time = timestamp
            st.image_count += 1
            # a frame that completes nothing leaves the gate alone (_completes, inline)
            job = self._completes(completed) if completed or self._gate is None else None
            if job is _WAKE or self._input_waiters:
                self.cond.notify_all()
        finally:
            self._release()
        if job is not None and job is not _WAKE:
            self._hand_off(job)
        return st

    def on_positions(self, slots: list[int], data: bytes | bytearray, timestamp: float = 0.0
                     ) -> None:
        """Store the positions of an encoder default PDO (wire time ``timestamp``).

        :param slots: the slots the PDO carries, in the order of its positions
        :param data: the PDO payload: REG_SSI_POS of each slot carried, 4 bytes little-endian
            each (a short payload is zero-padded)
        """
        if len(data) == POSITION_PAIR.size:
            values = POSITION_PAIR.unpack(data)
        else:
            values = POSITION_PAIR.unpack(bytes(data).ljust(POSITION_PAIR.size, b"\0"))
        job: Callable[[], None] | None = None
        self._acquire()
        try:
            if self.sink is not None:
                self.sink.positions(slots, timestamp, values)
            since = self._foreign_since
            if since is not None and timestamp > since:  # _foreign, inline
                self._count_foreign()
                return
            late = 0.0 < timestamp < self.sync_time  # _late, inline
            if late:
                self.late_frames += 1
            seq = self.sync_seq
            completed = False
            for slot, value in zip(slots, values):
                st = self._slots[slot]
                if late:
                    st.position_seq = max(st.position_seq, seq - 1)
                elif st.position_seq != seq:
                    st.position_seq = seq
                    self._due -= 1
                    completed = completed or self._due == 0
                st.position = value
                st.position_time = timestamp
            job = self._completes(completed) if completed or self._gate is None else None
            if job is _WAKE:
                self.cond.notify_all()
        finally:
            self._release()
        if job is not None and job is not _WAKE:
            self._hand_off(job)

    def _completes(self, completed: bool) -> Callable[[], None] | None:
        """Under the lock: what this frame does once the lock is released: :data:`_WAKE` the
        waiters (it completed the cycle of every station), run the cycle the cycle thread
        armed (``CycleGate.take``: the caller hands it off, the waiters are woken after it),
        or nothing (None)."""
        gate = self._gate
        if gate is None:
            return _WAKE if self._due == 0 else None
        if not completed:
            return None
        gate.pending -= 1
        if gate.pending > 0:
            return None
        job = gate.take()
        return _WAKE if job is None else job

    def _hand_off(self, job: Callable[[], None]) -> None:
        """Run the armed cycle this frame completed, out of the lock (``CycleGate.run``)."""
        assert self._gate is not None
        self._gate.run(job)

    def seq_at(self, t: float) -> int:
        """The number of the newest SYNC recorded at wire time ``t`` (the current one if none:
        ``t`` fell out of the kept times)."""
        with self.cond:
            for seq in range(self.sync_seq, max(self.sync_seq - _KEEP_SYNC_TIMES, 0), -1):
                if self._times.get(seq) == t:
                    return seq
            return self.sync_seq

    def latest(self, slot: int) -> ChannelSample | None:
        """The newest complete sample of ``slot`` or None before the first one."""
        with self.cond:
            st = self.slot(slot)
            if st.image is None or st.position is None:
                return None
            # the sample is as old as the older of its two frames
            seq = min(st.image_seq, st.position_seq)
            return ChannelSample(slot, st.position, st.image, self._times.get(seq, 0.0),
                                 st.image_count)

    @property
    def answering(self) -> bool:
        """True once any TPDO answered the current SYNC.

        A station's TPDOs follow the SYNC back to back, so a station that answered in part
        lost the rest on the wire, while one that answered nothing is silent or starved of CPU.
        """
        return self._due < 2 * self.slots

    def cycle_complete(self) -> bool:
        """True when every slot's image and position arrived since the last SYNC."""
        return self._due == 0

    def wait_cycle(self, timeout: float) -> bool:
        """Wait until :meth:`cycle_complete` or ``timeout`` (s) elapses."""
        with self.cond:
            return self.cond.wait_for(self.cycle_complete, timeout)

    def next_input(self, slot: int, timeout: float) -> ProcessInput | None:
        """Wait for an image newer than the slot's last output edit.

        :param slot: the module's slot (1-based)
        :param timeout: at most this long (s)
        :returns: the new image, decoded; None when none came within ``timeout``
        """
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
