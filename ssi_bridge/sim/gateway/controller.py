"""The gateway's CAN controller: a receive FIFO of a few frames, and when its firmware handles one.

A CAN controller holds the frames it received in a small receive FIFO until the device's
firmware takes them out; a frame that arrives while the FIFO is full is lost and the
controller flags an overrun (CiA 301 emergency error code 0x8110 "CAN overrun (objects
lost)"). :class:`RxFifo` models that FIFO for the simulated XN-GW-CANOPEN, ``RX_FIFO_DEPTH``
frames deep: what bxCAN (STM32) gives one receive FIFO (3 mailboxes), and about what the
SJA1000's 64-byte receive FIFO holds of 8-byte data frames (4). Manual 000 does not name the
gateway's controller; any such controller holds a handful of frames, not a backlog of
seconds. Only frames the gateway subscribes to enter it (its acceptance filter): NMT, SYNC,
its SDO requests and RPDOs.

The station is a process and its firmware a thread standing in for hardware. For each frame:

* ``w``: its wire time; ``arrival``: when it reached this process (the kernel's receive time
  on udp_multicast, later than ``w`` when the sending process woke late: the sender's delay,
  not this station's); ``now``: when the station's thread takes it.
* The station's own delay is ``d = now - arrival``. With ``d <= grace``
  (:data:`HANDLING_GRACE_S`) its thread was merely scheduled late, which a device's firmware
  is not: the frame counts as handled at ``w`` (a SYNC latches at its wire time) and left
  the FIFO then. Beyond the grace the device stalled: it handles the frame at ``w + d`` on
  the wire's time line (a SYNC latches when it is handled) and the frame left the FIFO only
  ``now``. Handling times never go backwards. Either way the station's answers go on the
  wire when they are really sent: nothing claims a wire time in the past.
* A frame is lost when the ``depth`` frames admitted before it had all not left the FIFO by
  its wire time: the FIFO was full. Each run of lost frames is one overrun episode.
* A station in its master's own process (python-can ``virtual``, :func:`in_process`) shares
  that process's CPU and GIL: its thread's delays are the process's, never a stall of the
  device alone, so there the grace is unbounded (:func:`grace_for`): it latches at the wire
  time and never overruns on its own. Stalls are a station process's (udp_multicast, a real
  interface), which can be starved or stopped (SIGSTOP) while its master runs on.
* ``queueing`` (the fault QUEUE_BACKLOG): a device that queues every frame in memory: nothing
  is lost and every frame counts as handled at its wire time (a SYNC latches there, however
  late it is handled; its answer still goes on the wire when it is really sent).

:class:`RxFifo` is pure (every time is passed in, no I/O); :class:`ControllerListener` puts
it on the gateway's receive path.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable

import can
import canopen

from can.interfaces.virtual import VirtualBus

from ssi_bridge.base.realtime import fifo_this_thread
from ssi_bridge.base.rx_guard import GuardedListener
from ssi_bridge.base.timebase import wire_now

logger = logging.getLogger(__name__)

#: frames the controller's receive FIFO holds (bxCAN: 3 mailboxes per FIFO)
RX_FIFO_DEPTH = 3
#: how late (s) the station's thread may take a frame after it reached this process with the
#: controller's FIFO still emptied on time (its interrupt runs; the firmware is only slow):
#: above the scheduling delay of a station process beside two CPU burners (the node itself
#: waits up to 20 ms for a starved station's answer, docs/node.md); a longer delay is a stall
#: of the device, during which the FIFO fills
HANDLING_GRACE_S = 0.02


def in_process(bus: can.BusABC) -> bool:
    """True when ``bus`` is python-can's in-process ``virtual`` bus (wrapped in a WireBus or
    LossyBus or not): its peers run in this process."""
    seen = 0
    while seen < 8 and not isinstance(bus, VirtualBus):
        inner = getattr(bus, "_inner", None)
        if inner is None:
            return False
        bus, seen = inner, seen + 1
    return isinstance(bus, VirtualBus)


def grace_for(bus: can.BusABC) -> float:
    """The handling grace of a gateway on ``bus``: unbounded in-process, else
    :data:`HANDLING_GRACE_S` (see the module doc)."""
    return float("inf") if in_process(bus) else HANDLING_GRACE_S


class RxFifo:
    """The receive FIFO of a CAN controller and its firmware's handling times (see module doc).

    :param depth: frames the FIFO holds (>= 1)
    :param grace: the thread delay (s) still counted as handling on time
    :raises ValueError: depth < 1 or grace < 0
    """

    def __init__(self, depth: int = RX_FIFO_DEPTH, grace: float = HANDLING_GRACE_S) -> None:
        if depth < 1:
            raise ValueError(f"receive FIFO depth {depth} must be >= 1")
        if not grace >= 0:
            raise ValueError(f"handling grace {grace} s must be >= 0")
        self.depth = depth
        self.grace = grace
        #: QUEUE_BACKLOG: keep every frame, handled at its wire time
        self.queueing = False
        #: frames lost to overruns (all episodes)
        self.lost = 0
        #: overrun episodes (runs of lost frames)
        self.overruns = 0
        #: frames lost in the episode in progress (0: none in progress)
        self.episode_lost = 0
        #: frames taken after a stall (later than the grace after their arrival)
        self.late = 0
        #: the largest firmware delay d seen (s)
        self.worst_delay = 0.0
        # when the last ``depth`` admitted frames left the FIFO (non-decreasing)
        self._left: deque[float] = deque(maxlen=depth)
        self._last_left = -float("inf")
        self._last_handled = -float("inf")

    def admit(self, wire_t: float, arrival: float, now: float) -> float | None:
        """The wire time at which the firmware handles a frame on the wire at ``wire_t`` that
        reached this process at ``arrival`` and that its thread takes at ``now``; None when the
        FIFO was full at ``wire_t`` (the frame is lost, counted in :attr:`lost`)."""
        if self.queueing:
            return wire_t
        left = self._left
        if len(left) == self.depth and left[0] > wire_t:
            self.lost += 1
            if not self.episode_lost:
                self.overruns += 1
            self.episode_lost += 1
            return None
        self.episode_lost = 0
        delay = now - arrival if now > arrival else 0.0
        if delay > self.worst_delay:
            self.worst_delay = delay
        if delay <= self.grace:
            out = handled = wire_t
        else:
            out, handled = now, wire_t + delay
            self.late += 1
        if out < self._last_left:
            out = self._last_left
        self._last_left = out
        left.append(out)
        if handled < self._last_handled:
            handled = self._last_handled
        self._last_handled = handled
        return handled

    def set_queueing(self, on: bool) -> None:
        """Queue every frame (QUEUE_BACKLOG) or hold ``depth`` again; forgets the FIFO.

        :param on: queue every frame (True) or hold the controller's depth (False)
        """
        self.queueing = bool(on)
        self._left.clear()
        self.episode_lost = 0


class ControllerListener(GuardedListener):
    """The gateway's receive path: :class:`GuardedListener` behind an :class:`RxFifo`.

    Subscribers get each frame with its firmware handling time (a SYNC latches then); a frame
    the FIFO lost reaches none. ``on_overrun(lost)`` is called (receive thread) with the
    total of lost frames at the first loss of each episode. ``priority``: the receive thread
    (which answers SYNCs) takes SCHED_FIFO ``priority`` with its first frame, as a station
    process's threads do (``simulation.station_priority``); it is the simulated firmware,
    and its delays put the station's answers late on the wire.

    :param network: the gateway's canopen network (its subscribers get the frames)
    :param name: names the listener in log lines
    :param fifo: the controller's receive FIFO
    :param on_overrun: called with the frames lost so far when an overrun episode begins
    :param clock: the wire clock the handling times are on
    :param priority: SCHED_FIFO priority of the receive thread (0: normal)
    """

    def __init__(self, network: canopen.Network, name: str, fifo: RxFifo,
                 on_overrun: Callable[[int], None], clock: Callable[[], float] = wire_now,
                 priority: int = 0) -> None:
        super().__init__(network, name)
        self.fifo = fifo
        self._on_overrun = on_overrun
        self._clock = clock
        # SCHED_FIFO priority the receive thread takes with its first frame (0: none)
        self._priority = priority

    def handling_time(self, msg: can.Message, wire_t: float) -> float | None:
        """When the firmware handles ``msg``, which ended on the wire at ``wire_t``: its time through
        the FIFO, or None when the FIFO was full and the frame is lost (an overrun).

        :param msg: the received frame
        :param wire_t: its wire time (s; 0: the frame's own timestamp)
        """
        if self._priority:
            priority, self._priority = self._priority, 0
            if not fifo_this_thread(priority):
                logger.info("%s: SCHED_FIFO %d not permitted, receiving normally", self.name,
                            priority)
        now = self._clock()
        stamp = msg.timestamp
        if not wire_t:
            wire_t = stamp or now
        arrival = stamp if stamp > wire_t else wire_t
        fifo = self.fifo
        episodes = fifo.overruns
        t = fifo.admit(wire_t, arrival, now)
        if t is None and fifo.overruns != episodes:
            self._on_overrun(fifo.lost)
        return t


__all__ = ["ControllerListener", "HANDLING_GRACE_S", "RX_FIFO_DEPTH", "RxFifo", "grace_for",
           "in_process"]
