"""The simulated CAN wire: frames take their real time at the bit rate, one at a time.

On a simulated interface (``virtual``, ``udp_multicast``) :func:`open_bus` returns a
:class:`WireBus`: frames take their real time on the wire at the bit rate, one at a time, and
carry their end-of-frame wire time (``protocol/wire.py``, ``base/timebase.py``). Every
:class:`WireBus` of one channel in a process shares one :class:`Wire`, so their frames never
overlap; frames of other processes (udp_multicast) extend its busy time when received.
:class:`DuePeriodicTask` runs a device's heartbeat on its own timer's schedule.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Sequence
from typing import Any

import can

from ssi_bridge.base.timebase import frame_wire_time, wire_now
from ssi_bridge.base.buses import open_python_can
from ssi_bridge.base.can_compat import is_shut_down, recv_step, steps_itself
from ssi_bridge.base.buses import take_bus as take_any_bus
from ssi_bridge.exceptions import BusError
from ssi_bridge.protocol.dictionary import SYNC_COB_ID
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.protocol.wire import frame_bits

logger = logging.getLogger(__name__)

#: python-can interfaces that are simulated wires: they get :class:`WireBus` (frame timing)
SIMULATED_INTERFACES = ("virtual", "udp_multicast")
#: how long (s) a periodic frame that is due but not sent yet holds a receiver's view of the
#: wire back (:meth:`Wire.owe`): longer than any starvation seen on a loaded machine, short
#: enough that a producer thread that hangs is still noticed
OWED_MAX_S = 1.0


def open_bus(config: BusConfig) -> can.BusABC:
    """Open a new python-can bus for ``config``; the caller must ``shutdown()`` it.

    A simulated interface (:data:`SIMULATED_INTERFACES`) comes wrapped in :class:`WireBus`, so
    its frames take their real time on the wire at ``config.bitrate`` (receivers on
    ``virtual`` see the WireBus end-of-frame time). Raises BusError.
    """
    bus = open_python_can(config, preserve_timestamps=True)
    if config.interface in SIMULATED_INTERFACES:
        return WireBus(bus, wire_for(config))
    return bus


class Wire:
    """The time line of one simulated CAN wire: busy until the end of the last frame on it.

    Shared by every :class:`WireBus` of one channel in a process (the gateway's and the
    master's), so their frames never overlap; frames from another process (udp_multicast)
    are learnt when they arrive (their timestamp is their end on the wire).

    :param bitrate: the wire's bit rate (bit/s)
    """

    def __init__(self, bitrate: int) -> None:
        self.bitrate = bitrate
        self.lock = threading.Lock()
        #: held while one frame is handed to the receivers: python-can's virtual bus puts a
        #: frame in each receiver's queue in turn, so without it two senders' frames could
        #: reach two nodes in different orders (a station's answer before the SYNC it
        #: answers), which a CAN wire never does
        self.broadcast = threading.Lock()
        #: wire time (s) at which the last frame known to this process ends
        self.busy_until = 0.0
        #: end (s) of the newest SYNC (COB-ID 0x080) put on this wire in this process
        self.last_sync = 0.0
        # frames on the wire not yet handed to the receivers (id -> end): a sender thread
        # that stalls after its frame ended delays the frame, not the wire's time line
        self._pending: dict[int, float] = {}
        # periodic producers of this process (key -> wire time their next frame is due)
        self._owed: dict[int, float] = {}

    def claim(self, bits: int, ready: float) -> float:
        """Put a frame of ``bits`` ready at ``ready`` on the wire; return its end (s)."""
        with self.lock:
            start = ready if ready > self.busy_until else self.busy_until
            end = start + bits / self.bitrate
            self.busy_until = end
            return end

    def claim_all(self, frames: Sequence[can.Message], ready: float,
                  answering: float | None = None) -> bool:
        """Stamp ``frames`` back to back from ``ready`` (or the end of the wire's last frame,
        whichever is later) with their ends; all or nothing.

        ``ready`` is the wire time at which the sender hands them over (:func:`wire_now` when
        they are really sent): no frame is ever stamped earlier than that, so a receiver that
        has seen the wire up to some instant never gets a frame claiming an earlier one.
        ``answering`` is the wire time of the SYNC these frames answer: when a newer SYNC is
        already on the wire as far as this process knows, they are not sent (False): a
        device sends a SYNC's synchronous TPDOs inside that SYNC's cycle, before the next
        SYNC (CiA 301 synchronous window), and a later answer would be taken for the newer
        SYNC's.
        """
        rate = self.bitrate
        with self.lock:
            if answering is not None and self.last_sync > answering:
                return False
            at = ready if ready > self.busy_until else self.busy_until
            pending = self._pending
            for msg in frames:
                at += frame_bits(msg.arbitration_id, msg.data, msg.is_remote_frame,
                                 msg.dlc) / rate
                msg.timestamp = at
                pending[id(msg)] = at
                if msg.arbitration_id == SYNC_COB_ID:
                    self.last_sync = at
            self.busy_until = at
            return True

    def delivered(self, msg: can.Message) -> None:
        """``msg`` (claimed here) has been handed to the receivers, or never will be."""
        with self.lock:
            self._pending.pop(id(msg), None)

    def owe(self, key: int, due: float | None) -> None:
        """The periodic producer ``key`` sends its next frame at wire time ``due`` (None: it
        sends nothing, e.g. muted or stopped)."""
        with self.lock:
            if due is None:
                self._owed.pop(key, None)
            else:
                self._owed[key] = due

    def undelivered_since(self) -> float:
        """End of the oldest frame claimed in this process and not yet handed over (inf: none).

        A receiver has seen the wire only up to just before it: a frame with that time stamp
        may still arrive (its sender's thread did not get to hand it over yet). A periodic
        frame of this process that is due but not sent yet counts the same, for up to
        :data:`OWED_MAX_S`: the simulated device's timer is hardware and sends on time; only
        the thread standing in for it is late.
        """
        with self.lock:
            oldest = min(self._pending.values(), default=math.inf)
            if self._owed:
                horizon = wire_now() - OWED_MAX_S
                for due in self._owed.values():
                    if horizon < due < oldest:
                        oldest = due
            return oldest

    def observe(self, end: float, sync: bool = False) -> None:
        """A frame of another process ended at ``end``: the wire was busy until then.

        :param end: the frame's end on the wire (s)
        :param sync: it was a SYNC
        """
        if sync and end > self.last_sync:
            self.last_sync = end
        if end > self.busy_until:
            with self.lock:
                if end > self.busy_until:
                    self.busy_until = end


_wires: dict[tuple[str, str, int], Wire] = {}
_wires_lock = threading.Lock()


def wire_for(config: BusConfig) -> Wire:
    """The process's :class:`Wire` of ``config``'s interface, channel and bit rate."""
    key = (config.interface, str(config.channel), config.bitrate)
    with _wires_lock:
        wire = _wires.get(key)
        if wire is None:
            wire = _wires[key] = Wire(config.bitrate)
        return wire


class WireBus(can.BusABC):
    """A simulated bus whose frames take their real time on the wire (CAN 2.0A at the bit rate).

    ``send`` puts the frame on the :class:`Wire` after whatever is on it (SOF to IFS with its
    actual stuff bits, ``protocol/wire.py``), stamps it with its end and hands it to the
    receivers only then (sleeping, not spinning: a late wake-up, docs/canopen.md "Time and
    the wire", does not add up over a burst because every frame's end is computed).
    :meth:`send_batch` sends frames that are ready together in arbitration order (lowest
    identifier first), as CAN arbitration would. Frames two nodes make ready within the same
    bit time are sent in the order they were handed over (first come), not arbitrated.
    Received frames extend the wire's busy time (frames of other processes).

    :param inner: the python-can bus the frames travel on
    :param wire: the wire's time line, shared by every end in the process
    """

    def __init__(self, inner: can.BusABC, wire: Wire) -> None:
        self._inner = inner
        self.wire = wire
        self._inner_steps = steps_itself(inner)
        # frames read ahead by :meth:`catch_up` (already observed), handed out first
        self._ahead: deque[can.Message] = deque()
        self._ahead_error: can.CanError | None = None
        super().__init__(channel=getattr(inner, "channel_info", "wire"))
        self.channel_info = f"wire({inner.channel_info}, {wire.bitrate} bit/s)"

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send one frame; returns when its last bit is on the wire.

        :param msg: the frame
        :param timeout: as python-can's ``BusABC.send``
        """
        self.send_batch([msg], timeout=timeout)

    def send_batch(self, msgs: Sequence[can.Message], answering: float | None = None,
                   timeout: float | None = None) -> bool:
        """Send frames ready at the same instant, lowest identifier first.

        ``answering``: the wire time of the SYNC they answer; if a newer SYNC is already on
        the wire the frames are not sent and False is returned (see :meth:`Wire.claim_all`).
        The frames are ready now, when this thread really hands them over: a sending thread
        that ran late (a station process starved or stopped) puts them on the wire late, as
        a late device does, and never claims a wire time in the past.

        :param msgs: the frames
        :param timeout: as python-can's ``BusABC.send``
        """
        ordered = sorted(msgs, key=lambda m: m.arbitration_id) if len(msgs) > 1 else msgs
        if answering is not None:
            self.catch_up()
        if not self.wire.claim_all(ordered, wire_now(), answering):
            return False
        delivered = self.wire.delivered
        try:
            for msg in ordered:
                wait = msg.timestamp - wire_now()
                if wait > 0:
                    time.sleep(wait)
                if is_shut_down(self):
                    return False  # shut down while the frame was on the wire: nobody gets it
                with self.wire.broadcast:
                    self._inner.send(msg, timeout)
                delivered(msg)
        finally:
            for msg in ordered:
                delivered(msg)
        return True

    def catch_up(self) -> None:
        """Read every frame already waiting for this bus (without waiting) and learn its place
        on the wire, so a newer SYNC that has reached this process is known before an answer
        to an older one is claimed (:meth:`Wire.claim_all`); :meth:`recv` hands them out in
        order. Call it from the thread that receives (the gateway answers a SYNC on it)."""
        if self._ahead_error is not None:
            return
        while True:
            try:
                msg = self._step(0.0)
            except can.CanError as err:  # handed to the receiver in turn, as recv would
                self._ahead_error = err
                return
            if msg is None:
                return
            self._ahead.append(msg)

    def _step(self, timeout: float | None) -> can.Message | None:
        """One frame from the wrapped bus (observed on the wire), or None after ``timeout``."""
        if self._inner_steps:
            msg = recv_step(self._inner, timeout)
        else:
            msg = self._inner.recv(timeout)
        if msg is not None:
            end = frame_wire_time(msg)
            if end:  # a frame of another process: the wire was busy until its end
                self.wire.observe(end, msg.arbitration_id == SYNC_COB_ID)
        return msg

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self._ahead:
            return self._ahead.popleft(), False
        err = self._ahead_error
        if err is not None:
            self._ahead_error = None
            raise err
        return self._step(timeout), False

    def shutdown(self) -> None:
        """Shut the wrapped bus down too."""
        super().shutdown()
        self._inner.shutdown()


def take_bus(source: BusConfig | can.BusABC | None, owner: str) -> can.BusABC:
    """The bus a gateway runs on: the simulated wire's for a config (:func:`open_bus`), or the
    one handed over (:func:`ssi_bridge.base.buses.take_bus`).

    :param source: a bus configuration or an open bus
    :param owner: names the taker in the error
    :raises BusError: the bus was handed over and shut down already
    """
    return take_any_bus(source, owner, open_bus)


class DuePeriodicTask:
    """A simulated device's periodic frame (its heartbeat), on the schedule of its own timer.

    A device's producer timer is hardware: its frames go out every ``period`` whatever else
    happens. The thread standing in for it can be starved of CPU on a loaded machine, so
    while its next frame is due but not sent the wire owes it (:meth:`Wire.owe`) and a
    receiver on this wire does not judge the wire past that due time: the thread's delay is
    not taken for the device's silence. A frame sent late is stamped when it is sent (the
    wire's order is the receivers' order), and slots missed meanwhile are skipped, not sent
    in a burst. A muted bus owes nothing (the "gateway silent" fault is a real silence).
    Implements what canopen's ``PeriodicMessageTask`` uses: ``stop()``, ``modify_data(msg)``.
    ``bus`` is the device's :class:`~ssi_bridge.sim.gateway.bus.LossyBus` (its ``muted``).

    :param bus: the device's bus
    :param wire: the wire's time line
    :param msg: the frame sent every period
    :param period: seconds between frames (> 0)
    :param autostart: start at once
    :raises ValueError: ``period`` not positive
    """

    def __init__(self, bus: Any, wire: Wire, msg: can.Message, period: float, *,
                 autostart: bool = True) -> None:
        if not period > 0:
            raise ValueError(f"period {period} s must be > 0")
        self.period = period
        self._bus = bus
        self._wire = wire
        self._msg = msg
        self._stopped = threading.Event()
        self._thread: threading.Thread | None = None
        if autostart:
            self.start()

    def start(self) -> None:
        """Send the first frame now and then every period until :meth:`stop`."""
        if self._thread is not None and self._thread.is_alive():
            return
        self._stopped.clear()
        self._thread = threading.Thread(target=self._run, daemon=True,
                                        name=f"periodic-0x{self._msg.arbitration_id:03X}")
        self._thread.start()

    def stop(self) -> None:
        """Stop sending; the wire owes nothing more (does not wait for the thread)."""
        self._stopped.set()
        self._wire.owe(id(self), None)

    def modify_data(self, msg: can.Message) -> None:
        """Send ``msg``'s data from the next frame on (canopen's ``update``: a new NMT state)."""
        self._msg = msg

    def _run(self) -> None:
        key, bus, wire, period = id(self), self._bus, self._wire, self.period
        due = wire_now()
        try:
            while not self._stopped.is_set():
                wait = due - wire_now()
                if wait > 0 and self._stopped.wait(wait):
                    break
                m = self._msg
                try:
                    bus.send(can.Message(arbitration_id=m.arbitration_id, data=bytes(m.data),
                                         is_extended_id=m.is_extended_id,
                                         is_remote_frame=m.is_remote_frame, dlc=m.dlc))
                except (can.CanError, BusError) as err:
                    logger.debug("periodic frame 0x%03X not sent: %s", m.arbitration_id, err)
                due += period
                late = wire_now() - due
                if late > 0:
                    due += period * math.ceil(late / period)  # skip the slots missed
                wire.owe(key, None if bus.muted else due)
        finally:
            wire.owe(key, None)


