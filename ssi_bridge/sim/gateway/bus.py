"""The simulated gateway's bus: the fault-injecting wrapper and canopen's network on it.

:class:`LossyBus` wraps the gateway's bus (a :class:`~ssi_bridge.sim.gateway.wire_bus.WireBus`
on a simulated interface) to drop a seeded fraction of frames ("CAN frame loss" fault) or to
go quiet entirely ("gateway silent"). :class:`BridgeNetwork` is the gateway's canopen
``Network``; its frames are cheap to deep-copy (:class:`WireMessage`). The timed wire itself,
:func:`open_bus` and :func:`take_bus` are in ``wire_bus.py`` (re-exported here).
"""

from __future__ import annotations

import logging
import random
import threading
from collections.abc import Callable, Sequence
from copy import deepcopy
from typing import Any

import can

from ssi_bridge.base.can_compat import recv_step, recv_step_unfiltered, steps_itself
from ssi_bridge.base.canopen_compat import OwnListenerNetwork
from ssi_bridge.exceptions import ConfigError
from ssi_bridge.sim.gateway.wire_bus import (
    OWED_MAX_S, SIMULATED_INTERFACES, DuePeriodicTask, Wire, WireBus, open_bus, take_bus, wire_for,
)

logger = logging.getLogger(__name__)

#: receive-thread wake-up period (s): bounds how long stopping a canopen Network takes
NOTIFIER_CYCLE = 0.05
class LossyBus(can.BusABC):
    """A bus wrapper that drops frames at ``loss_rate`` (seeded) and can be muted.

    Drops apply to sent and, if ``drop_received`` is set, to received frames. ``muted``
    swallows every frame this side sends (the "gateway silent" fault). Both can be changed
    at run time from any thread. Shutting the wrapper down shuts the wrapped bus down.

    :param inner: the bus wrapped (a simulated wire's bus or a real interface)
    :param loss_rate: share of frames dropped, 0-1
    :param seed: seed of the drop choice (None: unseeded)
    :param drop_received: drop received frames at ``loss_rate`` too
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
        # an inner bus with python-can's own recv() loop is read one receive step at a time
        # (its _recv_internal plus its filters): this wrapper's recv() is that same loop
        self._inner_steps = steps_itself(inner)
        super().__init__(channel=getattr(inner, "channel_info", "lossy"))
        self.channel_info = f"lossy({inner.channel_info})"

    @property
    def wire(self) -> Wire | None:
        """The simulated wire under this bus (a WireBus's), None on a real interface."""
        return self._wire

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
        """Send ``msg`` unless muted or chosen for dropping, waiting at most ``timeout`` s
        (None: the wrapped bus's default); raises what the wrapped bus raises."""
        if self.muted or (self._loss_rate > 0.0 and self._drop()):
            return
        self._inner.send(msg, timeout)

    def report(self, msg: can.Message) -> None:
        """Put ``msg`` on the wire even while muted or lossy: an error frame the simulated
        wire reports to the master (faults BUS_OFF / ERROR_PASSIVE, ``simulation.py``)."""
        self._inner.send(msg)

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
        """Send frames ready together (the wire orders them) minus those muted or dropped.

        :param msgs: the frames
        :param answering: wire time of the SYNC they answer (None: none); on a simulated wire
            they are not sent once a newer SYNC is on it
        :returns: False when the wire refused them for a newer SYNC, else True
        """
        if self.muted:
            return True
        if self._loss_rate > 0.0:
            msgs = [m for m in msgs if not self._drop()]
        batch = getattr(self._inner, "send_batch", None)
        if batch is not None:
            return bool(batch(msgs, answering))
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
        if (self._inner_steps and not self.drop_received and self.filters is None
                and self._inner.filters is None):
            msg = recv_step_unfiltered(self._inner, timeout)
        else:
            msg = super().recv(timeout)
        return msg

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        inner = self._inner
        if self._inner_steps:
            # one step of the inner bus: BusABC.recv (ours) retries until the timeout
            msg = recv_step(inner, timeout)
            if msg is None:
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


class BridgeNetwork(OwnListenerNetwork):
    """The gateway's canopen ``Network`` (``base/canopen_compat.OwnListenerNetwork``), sending
    :class:`WireMessage` frames; its listener is ``base/rx_guard.GuardedListener``'s
    controller model (``controller.py``)."""

    #: TPDO bursts not sent because a newer SYNC was already on the wire
    window_missed = 0

    def make_frame(self, can_id: int, data: bytes, remote: bool) -> WireMessage:
        """The frame sent: a :class:`WireMessage` (on a simulated wire its ``timestamp`` is
        then its end on the wire).

        :param can_id: the CAN identifier
        :param data: the payload (0-8 bytes)
        :param remote: a remote transmission request
        """
        return WireMessage.frame(can_id, data, remote)

    def send_messages(self, frames: Sequence[tuple[int, bytes]], answering: float | None = None
                      ) -> list[tuple[int, can.CanError]]:
        """Send data frames back to back under one lock; return those that failed.

        The same frames as :meth:`send_message` for each, in order, with nothing of another
        thread between them (a station's TPDOs after one SYNC); the lock is taken once. A
        frame the bus refuses (``can.CanError``) does not stop the others: it is returned with
        its error. RuntimeError when not connected.

        :param frames: (CAN identifier, payload) of each frame, in order
        :param answering: wire time of the SYNC they answer (None: none); on a simulated wire
            they are not sent, and :attr:`window_missed` counts it, once a newer SYNC is on it
        :returns: (CAN identifier, error) of each frame the bus refused
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
        return failed


__all__ = ["BridgeNetwork", "LossyBus", "NOTIFIER_CYCLE", "OWED_MAX_S", "SIMULATED_INTERFACES",
           "DuePeriodicTask", "Wire", "WireBus", "WireMessage", "open_bus", "take_bus", "wire_for"]
