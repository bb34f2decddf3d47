"""A canopen network listener that no frame, receive error or callback exception can stop.

python-can's ``Notifier`` runs the receive loop of a canopen ``Network``: an exception from
``bus.recv`` (an undecodable datagram on udp_multicast, an interface gone down) or from a
listener ends that thread unless a listener handles it in ``on_error``, and canopen's
``Network.check`` then raises the same exception at every later send (SYNC, NMT, SDO). A
subscriber that raises (a malformed frame on a COB-ID it handles) stops the other subscribers
of that frame. :class:`GuardedListener` is the one listener of the master's and the station's
networks, and:

* drops a frame on a COB-ID of :attr:`GuardedListener.rules` whose length its CiA 301
  service does not have (``protocol/frame_rules.py``: an empty heartbeat, a short SDO) before
  any subscriber decodes it (kind :data:`MALFORMED`); an owner reports a frame of the right
  length that its protocol still refuses (an SDO segment outside a transfer) through
  :meth:`GuardedListener.malformed` too;
* calls every subscriber of a frame on its own, so one that raises neither stops the others
  nor the receive path (kind :data:`CALLBACK_ERROR`);
* handles every receive error in ``on_error`` (kind :data:`UNDECODABLE` for a datagram that
  is not a CAN frame, :data:`RECEIVE_ERROR` for any other), and clears the notifier's record
  of it, so canopen's ``Network.check`` does not raise it at the next send;
* counts each kind (:attr:`GuardedListener.faults`, and :meth:`GuardedListener.count` for an
  owner that keeps its own counters) and logs it at most once per second per kind;
* pauses :data:`ERROR_PAUSE` after a receive error, so an interface that fails every call does
  not spin the receive thread.
"""

from __future__ import annotations

import logging
import time
import traceback
from collections import Counter
from collections.abc import Callable
from typing import Any

import can
import canopen

from ssi_bridge.base.canopen_compat import (
    Subscriber, dispatcher, forget_receive_error, subscribers,
)
from ssi_bridge.base.rate_log import RateLimitedLog
from ssi_bridge.base.timebase import WireTimeListener, frame_wire_time
from ssi_bridge.base.udp_bus import UndecodableFrame
from ssi_bridge.protocol.frame_rules import FrameRule

logger = logging.getLogger(__name__)

#: a received datagram that is not a CAN frame (``base/udp_bus.UndecodableFrame``)
UNDECODABLE = "undecodable_frames"
#: an error of the bus's receive call other than an undecodable datagram (e.g. ENETDOWN)
RECEIVE_ERROR = "receive_errors"
#: an exception raised by a subscriber of a received frame
CALLBACK_ERROR = "callback_errors"
#: a frame its CiA 301 service does not allow (a length, a sequence), dropped undecoded
MALFORMED = "malformed_frames"
#: the receive thread rests this long (s) after a receive error before it calls recv again
ERROR_PAUSE = 0.005


def receive_error_kind(exc: BaseException) -> str:
    """The fault kind a receive error ``exc`` counts as: :data:`UNDECODABLE` for a datagram
    that is no CAN frame, else :data:`RECEIVE_ERROR`."""
    return UNDECODABLE if isinstance(exc, UndecodableFrame) else RECEIVE_ERROR


def raised_at(err: BaseException) -> str:
    """``file:line`` where ``err`` was raised (its innermost frame), for a one-line log."""
    frames = traceback.extract_tb(err.__traceback__)
    if not frames:
        return "?"
    last = frames[-1]
    return f"{last.filename.rsplit('/', 1)[-1]}:{last.lineno}"


class GuardedListener(WireTimeListener):
    """canopen's network listener (wire times) that survives every fault of a frame or a bus.

    :param network: the canopen network it feeds
    :param name: who receives ("master", "gateway node 1"), for the log lines
    """

    def __init__(self, network: canopen.Network, name: str = "receive path") -> None:
        super().__init__(network)
        self.name = name
        #: faults by kind (:data:`UNDECODABLE`, :data:`RECEIVE_ERROR`, :data:`CALLBACK_ERROR`,
        #: :data:`MALFORMED`)
        self.faults: Counter[str] = Counter()
        #: COB-ID -> the length its service's frames have (``protocol/frame_rules.py``); the
        #: owner fills it with the COB-IDs it consumes
        self.rules: dict[int, FrameRule] = {}
        #: COB-ID -> the handler the network's owner routes it to (``OwnListenerNetwork.route``)
        self._routes: dict[int, Subscriber] = getattr(network, "routes", {})
        #: True when :meth:`handling_time` is this class's (the wire time itself)
        self._plain_time = type(self).handling_time is GuardedListener.handling_time
        self._log = RateLimitedLog(logger)
        #: canopen's notify of one frame to the network's subscribers, each on its own
        self._dispatch = dispatcher(network, self._raised)

    def count(self, kind: str) -> None:
        """One fault of ``kind`` (receive thread); an owner overrides it to count it too."""
        self.faults[kind] += 1

    def on_message_received(self, msg: can.Message) -> None:
        """Dispatch ``msg`` to each subscriber of its COB-ID on its own (wire time)."""
        if msg.is_error_frame or msg.is_remote_frame:
            return
        network = self.network
        can_id = msg.arbitration_id
        rule = self.rules.get(can_id)
        if rule is not None and len(msg.data) != rule.length:
            self.malformed(can_id, msg.data, rule.problem(len(msg.data)) or "")
            return
        route = self._routes.get(can_id)
        subscribed = subscribers(network, can_id)
        wire_t = 0.0
        if route is not None or subscribed:
            wire_t = frame_wire_time(msg)
            if not self._plain_time:
                handled_at = self.handling_time(msg, wire_t)
                if handled_at is None:
                    return  # not handled (a receiver that models its controller lost it)
                wire_t = handled_at
        if route is not None:
            try:
                route(can_id, msg.data, wire_t)
            except Exception as err:  # noqa: BLE001 - as dispatch: counted, receiving goes on
                self._raised(route, can_id, msg.data, err)
        self._dispatch(can_id, msg.data, wire_t)

    def _raised(self, callback: Callable[..., Any], can_id: int, data: bytearray,
                err: Exception) -> None:
        """A subscriber of frame ``can_id`` raised ``err``: counted as :data:`CALLBACK_ERROR`
        and logged (at most once per second)."""
        self.count(CALLBACK_ERROR)
        self._log.error(CALLBACK_ERROR, "%s: frame 0x%03X [%s] raised in %s: %r at %s; "
                        "receiving goes on", self.name, can_id, data.hex(" "),
                        getattr(callback, "__qualname__", callback), err, raised_at(err))

    def malformed(self, can_id: int, data: bytes | bytearray, why: str) -> None:
        """A frame its service does not allow (receive thread): counted as :data:`MALFORMED`
        and logged (at most once per second), never decoded.

        :param can_id: the frame's CAN identifier
        :param data: its payload
        :param why: what is wrong with it (ends the log line)
        """
        self.count(MALFORMED)
        self._log.warning(MALFORMED, "%s: frame 0x%03X [%s] with %d byte(s) is %s: dropped "
                          "(%d malformed so far)", self.name, can_id, bytes(data).hex(" "),
                          len(data), why, self.faults[MALFORMED])

    def handling_time(self, msg: can.Message, wire_t: float) -> float | None:
        """The time handed to the subscribers of ``msg`` (a frame someone subscribed to, on
        the wire at ``wire_t``): ``wire_t`` itself. A subclass that models a receiver's
        controller returns when its firmware handles the frame, or None for a frame it lost
        (the subscribers do not get it)."""
        return wire_t

    def on_error(self, exc: Exception) -> None:
        """A receive error ``exc`` (receive thread): counted and logged; receiving goes on."""
        forget_receive_error(self.network, exc)  # handled: canopen's check() must not raise it
        if receive_error_kind(exc) == UNDECODABLE:
            self.count(UNDECODABLE)
            self._log.warning(UNDECODABLE, "%s: dropped a datagram that is not a CAN frame: %s",
                              self.name, exc)
            return
        self.count(RECEIVE_ERROR)
        self._log.error(RECEIVE_ERROR, "%s: receive error, receiving goes on: %r", self.name,
                        exc)
        time.sleep(ERROR_PAUSE)


__all__ = ["CALLBACK_ERROR", "ERROR_PAUSE", "GuardedListener", "MALFORMED", "RECEIVE_ERROR",
           "UNDECODABLE", "raised_at", "receive_error_kind"]
