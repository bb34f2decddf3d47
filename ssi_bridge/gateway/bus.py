"""CAN bus configuration and the fault-injecting bus wrapper shared by gateway and client.

The station and the master each open their own python-can ``Bus`` on the same channel (on the
default in-process ``virtual`` interface every bus sees the frames the others send, as on a
real wire). :class:`LossyBus` wraps any bus to drop a seeded fraction of frames ("CAN frame
loss" fault) or to go quiet entirely ("gateway silent"). :class:`BridgeNetwork` is the
canopen ``Network`` both sides use; its frames are cheap to deep-copy (:class:`WireMessage`).
On a simulated interface (``virtual``, ``udp_multicast``) :func:`open_bus` returns a
:class:`WireBus`: frames take their real time on the wire at the bit rate, one at a time, and
carry their end-of-frame wire time (``gateway/wire.py``, ``gateway/timebase.py``).
"""

from __future__ import annotations

import logging
import math
import random
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from copy import deepcopy
from dataclasses import dataclass
from typing import Any

import can
import canopen
from canopen.network import MessageListener

from ssi_bridge.exceptions import BusError, ConfigError
from ssi_bridge.gateway.timebase import frame_wire_time, wire_now
from ssi_bridge.gateway.wire import frame_bits

logger = logging.getLogger(__name__)

#: bit rates a CANopen device must support or may support (CiA 301 / CiA 102), bit/s
#: receive-thread wake-up period (s): bounds how long stopping a canopen Network takes
NOTIFIER_CYCLE = 0.05
#: python-can interfaces that are simulated wires: they get :class:`WireBus` (frame timing)
SIMULATED_INTERFACES = ("virtual", "udp_multicast")
#: CiA 301 SYNC COB-ID (the wire remembers the newest SYNC for the synchronous window)
SYNC_COB_ID = 0x080
CIA_BITRATES = (10_000, 20_000, 50_000, 125_000, 250_000, 500_000, 800_000, 1_000_000)
#: frames a wire remembers (start, end) to fit a late answer in behind its SYNC
_RECENT_FRAMES = 64
#: how long (s) a periodic frame that is due but not sent yet holds a receiver's view of the
#: wire back (:meth:`Wire.owe`): longer than any starvation seen on a loaded machine, short
#: enough that a producer thread that hangs is still noticed
OWED_MAX_S = 1.0


@dataclass(frozen=True)
class BusConfig:
    """Where the gateway and the client meet: python-can interface, channel, bit rate, node."""

    #: python-can interface name ("virtual", "socketcan", "pcan", ...)
    interface: str = "virtual"
    #: python-can channel (virtual: any string; every bus on the same string is one wire)
    channel: str = "ssi_bridge"
    #: bit rate in bit/s, one of :data:`CIA_BITRATES` (the simulated wire times frames at it)
    bitrate: int = 500_000
    #: CANopen node id of the XN-GW-CANOPEN (1-127)
    node_id: int = 1

    def __post_init__(self) -> None:
        if not self.interface:
            raise ConfigError("BusConfig.interface must name a python-can interface")
        if self.channel in ("", None):
            raise ConfigError("BusConfig.channel must not be empty")
        if self.bitrate not in CIA_BITRATES:
            raise ConfigError(
                f"BusConfig.bitrate {self.bitrate} bit/s is not a CiA bit rate {CIA_BITRATES}")
        if not 1 <= self.node_id <= 127:
            raise ConfigError(f"BusConfig.node_id {self.node_id} outside 1-127")


def open_bus(config: BusConfig) -> can.BusABC:
    """Open a new python-can bus for ``config``; the caller must ``shutdown()`` it.

    A simulated interface (:data:`SIMULATED_INTERFACES`) comes wrapped in :class:`WireBus`, so
    its frames take their real time on the wire at ``config.bitrate``.
    """
    if config.interface == "udp_multicast":  # our own-frame-free variant (gateway/multicast)
        from ssi_bridge.gateway.multicast import open_udp_bus
        try:
            return WireBus(open_udp_bus(str(config.channel)), wire_for(config))
        except (can.CanError, OSError) as err:
            raise BusError(f"cannot open CAN bus udp_multicast:{config.channel}: {err}") from err
    kwargs: dict[str, Any] = {"interface": config.interface, "channel": config.channel}
    if config.interface == "virtual":
        kwargs["preserve_timestamps"] = True  # receivers see the WireBus end-of-frame time
    elif config.interface != "udp_multicast":
        kwargs["bitrate"] = config.bitrate
    try:
        bus = can.Bus(**kwargs)
    except (can.CanError, OSError, ValueError, ImportError) as err:
        raise BusError(
            f"cannot open CAN bus {config.interface}:{config.channel} "
            f"at {config.bitrate} bit/s: {err}") from err
    logger.debug("opened %s:%s", config.interface, config.channel)
    if config.interface in SIMULATED_INTERFACES:
        return WireBus(bus, wire_for(config))
    return bus


class Wire:
    """The time line of one simulated CAN wire: busy until the end of the last frame on it.

    Shared by every :class:`WireBus` of one channel in a process (the gateway's and the
    master's), so their frames never overlap; frames from another process (udp_multicast)
    are learnt when they arrive (their timestamp is their end on the wire).
    """

    def __init__(self, bitrate: int) -> None:
        self.bitrate = bitrate
        self.lock = threading.Lock()
        #: wire time (s) at which the last frame known to this process ends
        self.busy_until = 0.0
        #: end (s) of the newest SYNC (COB-ID 0x080) put on this wire in this process
        self.last_sync = 0.0
        # frames on the wire not yet handed to the receivers (id -> end): a sender thread
        # that stalls after its frame ended delays the frame, not the wire's time line
        self._pending: dict[int, float] = {}
        # (start, end) of the newest frames known here: where an answer to a SYNC fits
        self._recent: deque[tuple[float, float]] = deque(maxlen=_RECENT_FRAMES)
        # periodic producers of this process (key -> wire time their next frame is due)
        self._owed: dict[int, float] = {}

    def claim(self, bits: int, ready: float) -> float:
        """Put a frame of ``bits`` ready at ``ready`` on the wire; return its end (s)."""
        with self.lock:
            start = ready if ready > self.busy_until else self.busy_until
            end = start + bits / self.bitrate
            self.busy_until = end
            self._recent.append((start, end))
            return end

    def _first_gap(self, ready: float, length: float) -> float:
        """The earliest start at or after ``ready`` where ``length`` s fit between the frames
        known here (call under the lock)."""
        start = ready
        for s, e in sorted(self._recent):
            if e <= start:
                continue
            if s >= start + length:
                break
            start = e
        return start

    def claim_all(self, frames: Sequence[can.Message], ready: float,
                  answering: float | None = None) -> bool:
        """Stamp ``frames`` back to back from ``ready`` with their ends; all or nothing.

        ``answering`` is the wire time of the SYNC these frames answer: when a newer SYNC is
        already on the wire they are not sent (False). A CANopen device sends synchronous
        TPDOs inside the cycle of their SYNC (CiA 301 synchronous window), so a master can
        tell which SYNC a TPDO belongs to by its order on the wire. Such frames go in the
        first gap after their SYNC long enough for them, not behind every frame known: a
        station process that gets to its SYNCs late (starved) answers each where it would
        have, before the heartbeat its other thread sent meanwhile, instead of behind it and
        so inside a newer SYNC's cycle.
        """
        rate = self.bitrate
        lengths = [frame_bits(m.arbitration_id, m.data, m.is_remote_frame, m.dlc) / rate
                   for m in frames]
        with self.lock:
            if answering is not None:
                if self.last_sync > answering:
                    return False
                at = self._first_gap(ready, sum(lengths))
            else:
                at = ready if ready > self.busy_until else self.busy_until
            for msg, length in zip(frames, lengths):
                self._recent.append((at, at + length))
                at += length
                msg.timestamp = at
                self._pending[id(msg)] = at
                if msg.arbitration_id == SYNC_COB_ID:
                    self.last_sync = at
            if at > self.busy_until:
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

    def observe(self, end: float, sync: bool = False, length: float = 0.0) -> None:
        """A frame of another process (``length`` s long) ended at ``end``: the wire was busy
        until then."""
        if sync and end > self.last_sync:
            self.last_sync = end
        if end > self.busy_until:
            with self.lock:
                if end > self.busy_until:
                    self.busy_until = end
                    self._recent.append((end - length, end))


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
    actual stuff bits, ``gateway/wire.py``), stamps it with its end and hands it to the
    receivers only then (sleeping, not spinning: Python sleeps ~0.05-0.1 ms late, which does
    not add up over a burst because every frame's end is computed, not measured).
    :meth:`send_batch` sends frames that are ready together in arbitration order (lowest
    identifier first), as CAN arbitration would. Frames two nodes make ready within the same
    bit time are sent in the order they were handed over (first come), not arbitrated.
    Received frames extend the wire's busy time (frames of other processes).
    """

    def __init__(self, inner: can.BusABC, wire: Wire) -> None:
        self._inner = inner
        self.wire = wire
        self._inner_steps = type(inner).recv is can.BusABC.recv
        super().__init__(channel=getattr(inner, "channel_info", "wire"))
        self.channel_info = f"wire({inner.channel_info}, {wire.bitrate} bit/s)"

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send one frame; returns when its last bit is on the wire."""
        self.send_batch([msg], timeout=timeout)

    def send_batch(self, msgs: Sequence[can.Message], answering: float | None = None,
                   timeout: float | None = None) -> bool:
        """Send frames ready at the same instant, lowest identifier first.

        ``answering``: the wire time of the SYNC they answer; if a newer SYNC is already on
        the wire the frames are not sent and False is returned (see :meth:`Wire.claim_all`).
        Otherwise they are ready at that SYNC's end, not when this thread got to them: the
        simulated device answers on the wire's time line (in the first gap after its SYNC),
        as a real one does inside its SYNC's cycle. A sending thread that ran late (a station
        process starved under load) then neither stamps its answer into the next SYNC's
        cycle (where the master would count it) nor sleeps again for frames already over.
        """
        ordered = sorted(msgs, key=lambda m: m.arbitration_id) if len(msgs) > 1 else msgs
        ready = wire_now() if answering is None else answering
        if not self.wire.claim_all(ordered, ready, answering):
            return False
        delivered = self.wire.delivered
        try:
            for msg in ordered:
                wait = msg.timestamp - wire_now()
                if wait > 0:
                    time.sleep(wait)
                if self._is_shutdown:
                    return False  # shut down while the frame was on the wire: nobody gets it
                self._inner.send(msg, timeout)
                delivered(msg)
        finally:
            for msg in ordered:
                delivered(msg)
        return True

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self._inner_steps:
            msg, filtered = self._inner._recv_internal(timeout)
            if msg is not None and not filtered and not self._inner._matches_filters(msg):
                return None, False
        else:
            msg = self._inner.recv(timeout)
        if msg is not None:
            end = frame_wire_time(msg)
            if end > self.wire.busy_until:  # a frame of another process: its place in time
                self.wire.observe(end, msg.arbitration_id == SYNC_COB_ID, frame_bits(
                    msg.arbitration_id, msg.data, msg.is_remote_frame, msg.dlc)
                    / self.wire.bitrate)
            elif end:
                self.wire.observe(end, msg.arbitration_id == SYNC_COB_ID)
        return msg, False

    def shutdown(self) -> None:
        """Shut the wrapped bus down too."""
        super().shutdown()
        self._inner.shutdown()


def take_bus(source: BusConfig | can.BusABC | None, owner: str) -> can.BusABC:
    """The bus a gateway or master runs on: a new one for a config, or the one handed over.

    A handed-over bus belongs to its taker, which shuts it down when it stops; so it can be
    taken once. ``owner`` ("this gateway", ...) names the taker in the error.
    """
    if isinstance(source, BusConfig):
        return open_bus(source)
    if source is None:
        raise BusError(f"{owner}'s bus was handed over and already shut down")
    return source


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
    """

    def __init__(self, bus: LossyBus, wire: Wire, msg: can.Message, period: float, *,
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


class LossyBus(can.BusABC):
    """A bus wrapper that drops frames at ``loss_rate`` (seeded) and can be muted.

    Drops apply to sent and, if ``drop_received`` is set, to received frames. ``muted``
    swallows every frame this side sends (the "gateway silent" fault). Both can be changed
    at run time from any thread. Shutting the wrapper down shuts the wrapped bus down.
    """

    def __init__(self, inner: can.BusABC, loss_rate: float = 0.0, *, seed: int | None = 0,
                 drop_received: bool = False) -> None:
        self._inner = inner
        #: the simulated wire under this bus (a WireBus's), None on a real interface
        self._wire: Wire | None = getattr(inner, "wire", None)
        self._rng = random.Random(seed)
        self._rng_lock = threading.Lock()
        self.loss_rate = loss_rate
        self.drop_received = drop_received
        #: when True nothing this side sends reaches the wire
        self.muted = False
        #: frames dropped so far (sent + received)
        self.dropped = 0
        #: newest timestamp of a frame this side has handled, and the wire time at which a
        #: receive last found nothing waiting: what the receive path has seen of the wire
        self.rx_latest = 0.0
        self.rx_idle_at = 0.0
        # an inner bus with python-can's own recv() loop is read one receive step at a time
        # (its _recv_internal plus its filters): this wrapper's recv() is that same loop
        self._inner_steps = type(inner).recv is can.BusABC.recv
        super().__init__(channel=getattr(inner, "channel_info", "lossy"))
        self.channel_info = f"lossy({inner.channel_info})"

    @property
    def loss_rate(self) -> float:
        """Fraction of frames dropped, 0.0-1.0."""
        return self._loss_rate

    @loss_rate.setter
    def loss_rate(self, value: float) -> None:
        if not 0.0 <= value <= 1.0:
            raise ConfigError(f"loss_rate {value} outside 0.0-1.0")
        self._loss_rate = float(value)

    def _drop(self) -> bool:
        if self._loss_rate <= 0.0:
            return False
        with self._rng_lock:
            hit = self._rng.random() < self._loss_rate
        if hit:
            self.dropped += 1
        return hit

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send ``msg`` unless muted or chosen for dropping."""
        if self.muted or (self._loss_rate > 0.0 and self._drop()):
            return
        self._inner.send(msg, timeout)

    def _send_periodic_internal(self, msgs: can.Message | Sequence[can.Message], period: float,
                                duration: float | None = None, autostart: bool = True,
                                modifier_callback: Callable[[can.Message], None] | None = None,
                                ) -> Any:
        """On a simulated wire one periodic frame (canopen's heartbeat producer) runs on its
        due times (:class:`DuePeriodicTask`); anything else as python-can does it."""
        wire = self._wire
        single = msgs if isinstance(msgs, can.Message) else (msgs[0] if len(msgs) == 1 else None)
        if wire is None or single is None or duration is not None or modifier_callback:
            return super()._send_periodic_internal(msgs, period, duration, autostart,
                                                   modifier_callback)
        return DuePeriodicTask(self, wire, single, period, autostart=autostart)

    def send_batch(self, msgs: Sequence[can.Message], answering: float | None = None) -> bool:
        """Send frames ready together (the wire orders them) minus those muted or dropped."""
        if self.muted:
            return True
        if self._loss_rate > 0.0:
            msgs = [m for m in msgs if not self._drop()]
        batch = getattr(self._inner, "send_batch", None)
        if batch is not None:
            return batch(msgs, answering)
        for msg in msgs:
            self._inner.send(msg)
        return True

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """Receive one frame, as python-can's ``BusABC.recv``; None when ``timeout`` passed.

        While neither bus filters and no received frame is to be dropped, ``BusABC.recv`` is
        just the inner bus's receive step (a frame, or None after ``timeout``), so that step
        is taken directly: this is the path of every frame the receive thread reads. (The
        step skips python-can's level-9 "Received" trace of the ``can.bus`` logger.)
        """
        if (self._inner_steps and not self.drop_received and self._filters is None
                and self._inner.filters is None):
            msg = self._inner._recv_internal(timeout)[0]
        else:
            msg = super().recv(timeout)
        # what this side has seen of the wire, never past a frame of this process that is
        # still on its way (claimed, or a periodic frame due): it may land behind this one
        wire = self._wire
        if msg is None:
            now = wire_now()
            self.rx_idle_at = now if wire is None else min(now, wire.undelivered_since())
        elif msg.timestamp > self.rx_latest:
            ts = msg.timestamp
            self.rx_latest = ts if wire is None else min(ts, wire.undelivered_since())
        return msg

    def seen_until(self) -> float:
        """Wire time up to which every frame on the wire has been handled by this side.

        Never past a frame of this process that is on the wire but not handed over yet
        (:meth:`Wire.undelivered_since`): its sender's thread may be the one stalled.
        """
        seen = max(self.rx_latest, self.rx_idle_at)
        if self._wire is not None:
            seen = min(seen, self._wire.undelivered_since())
        return seen

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        inner = self._inner
        if self._inner_steps:
            # one step of the inner bus: BusABC.recv (ours) retries until the timeout
            msg, filtered = inner._recv_internal(timeout)
            if msg is not None and not filtered and not inner._matches_filters(msg):
                return None, False
        else:
            msg = inner.recv(timeout)
        if msg is not None and self.drop_received and self._drop():
            return None, False
        return msg, False

    def shutdown(self) -> None:
        """Shut the wrapped bus down too."""
        super().shutdown()
        self._inner.shutdown()


_new_message = can.Message.__new__


class WireMessage(can.Message):
    """A ``can.Message`` whose deep copy builds the payload copy directly.

    python-can's ``virtual`` interface hands each receiving bus ``deepcopy(msg)``, and
    ``Message.__deepcopy__`` copies the ``data`` bytearray through ``copy.deepcopy``'s generic
    reduce protocol, the largest part of sending a frame in-process. Here the copy is a
    plain ``can.Message`` with every field of the original and a new bytearray of the
    payload: the same independent deep copy. Other interfaces never copy.
    """

    __slots__ = ()

    @classmethod
    def frame(cls, can_id: int, data: bytes | bytearray | Sequence[int] | None,
              remote: bool = False) -> WireMessage:
        """The frame canopen's ``Network.send_message`` sends, built field by field.

        Equal in every field to ``Message(arbitration_id=can_id, is_extended_id=can_id >
        0x7FF, data=data, is_remote_frame=remote)`` (checked by test_pdo_readers) at a third
        of the cost of ``Message.__init__``'s keyword handling, paid once per frame sent.
        """
        msg = _new_message(cls)
        payload = bytearray() if remote or data is None else bytearray(data)
        msg.timestamp = 0.0
        msg.arbitration_id = can_id
        msg.is_extended_id = can_id > 0x7FF
        msg.is_remote_frame = remote
        msg.is_error_frame = False
        msg.channel = None
        msg.dlc = len(payload)
        msg.data = payload
        msg.is_fd = False
        msg.is_rx = True
        msg.bitrate_switch = False
        msg.error_state_indicator = False
        return msg

    def __deepcopy__(self, memo: dict[int, Any] | None) -> can.Message:
        # every field of can.Message (its __slots__; test_pdo_readers checks none is missed),
        # assigned directly: Message.__init__ with keywords costs twice as much per frame
        clone = _new_message(can.Message)
        clone.timestamp = self.timestamp
        clone.arbitration_id = self.arbitration_id
        clone.is_extended_id = self.is_extended_id
        clone.is_remote_frame = self.is_remote_frame
        clone.is_error_frame = self.is_error_frame
        channel = self.channel
        clone.channel = (channel if isinstance(channel, (str, int, type(None)))
                         else deepcopy(channel, memo))
        clone.dlc = self.dlc
        clone.data = bytearray(self.data)
        clone.is_fd = self.is_fd
        clone.is_rx = self.is_rx
        clone.bitrate_switch = self.bitrate_switch
        clone.error_state_indicator = self.error_state_indicator
        return clone


class WireTimeListener(MessageListener):
    """canopen's network listener, handing subscribers each frame's wire time.

    canopen passes ``msg.timestamp`` on: on udp_multicast the receive time, late by however
    long the sending process slept past the frame's end. This passes
    :func:`~ssi_bridge.gateway.timebase.frame_wire_time` instead (the same value on every
    other interface), so a station latches on the instant its SYNC was on the wire.
    """

    def on_message_received(self, msg: can.Message) -> None:
        """Dispatch ``msg`` to the network's subscribers with its wire time."""
        if msg.is_error_frame or msg.is_remote_frame:
            return
        try:
            self.network.notify(msg.arbitration_id, msg.data, frame_wire_time(msg))
        except Exception as err:  # noqa: BLE001 - as canopen's: a callback must not stop it
            logger.error("%s", err)


class BridgeNetwork(canopen.Network):
    """canopen's ``Network`` sending :class:`WireMessage` frames.

    ``Network.send_message`` is canopen's documented hook for a custom back end; everything
    canopen sends through it (NMT, SYNC, SDO, EMCY, PDOs) goes out unchanged on the wire, with
    the same lock and the same check of the receive thread.
    """

    #: called with every frame :meth:`send_message` sent (the master's bus load)
    on_sent: Callable[[can.Message], None] | None = None
    #: TPDO bursts not sent because a newer SYNC was already on the wire
    window_missed = 0

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> WireMessage:
        """Send one frame and return it (raises ``can.CanError``, RuntimeError when not
        connected). On a simulated wire its ``timestamp`` is then its end on the wire."""
        if not self.bus:
            raise RuntimeError("Not connected to CAN bus")
        frame = WireMessage.frame(can_id, data, remote)
        with self.send_lock:
            self.bus.send(frame)
        self.check()
        if self.on_sent is not None:
            self.on_sent(frame)
        return frame

    def send_messages(self, frames: Sequence[tuple[int, bytes]], answering: float | None = None
                      ) -> list[tuple[int, can.CanError]]:
        """Send data frames back to back under one lock; return those that failed.

        The same frames as :meth:`send_message` for each, in order, with nothing of another
        thread between them (a station's TPDOs after one SYNC); the lock and the receive
        thread check are paid once. A frame the bus refuses (``can.CanError``) does not stop
        the others: it is returned with its error. RuntimeError when not connected.
        """
        bus = self.bus
        if not bus:
            raise RuntimeError("Not connected to CAN bus")
        failed: list[tuple[int, can.CanError]] = []
        frame = WireMessage.frame
        batch = getattr(bus, "send_batch", None)
        with self.send_lock:
            if batch is not None:
                try:
                    if not batch([frame(can_id, data) for can_id, data in frames], answering):
                        self.window_missed += 1
                except can.CanError as err:
                    failed = [(frames[0][0], err)]
            else:
                for can_id, data in frames:
                    try:
                        bus.send(frame(can_id, data))
                    except can.CanError as err:
                        failed.append((can_id, err))
        self.check()
        return failed
