"""The master's receive path: frame counting and the TPDOs it configured, as raw frames.

canopen hands a received PDO to its ``PdoMap`` (a condition variable, the callback list, the
map object), and every frame passes the network's listeners. The bridge knows what its TPDOs
carry because it mapped them itself (``client/sdo.py``, 000 Table 15): TPDO s = the 8-byte
process input image of slot s (0x2000:s), TPDO 9.. = 0x6820 of a slot pair (Integer32 each).
So :class:`TpdoRoutes` subscribes the client's handlers to those COB-IDs directly and, after
every (re)configuration, takes canopen's ``PdoMap`` handlers that ``PdoMap.save`` subscribed
off them again: each frame is handled once, from its raw bytes. The SDO configuration itself
is unchanged. :class:`FrameListener` is canopen's network listener plus the frame counters;
it hands the subscribers each frame's wire time (``base/timebase.frame_wire_time``), so a
TPDO is matched to the SYNC it followed on the wire, not to the one current when it arrived
(between processes the arrival is late by however long its sender slept past its end).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from functools import partial

import can
import canopen

from ssi_bridge.client.load import BusLoad
from ssi_bridge.client.samples import ClientCounters
from ssi_bridge.client.sdo import position_pdos
from ssi_bridge.base.canopen_compat import OwnListenerNetwork, pdo_handler, subscribers
from ssi_bridge.base.rx_guard import GuardedListener
from ssi_bridge.client.error_frames import ErrorFrameWatch
from ssi_bridge.protocol.can_errors import BUS_OFF
from ssi_bridge.client.foreign import ForeignTraffic
from ssi_bridge.protocol.dictionary import tpdo_cob_base
from ssi_bridge.base.realtime import run_this_thread_at

logger = logging.getLogger(__name__)

#: kernel name of the master's receive thread (``top -H``)
RX_THREAD_NAME = "ssi_can_rx"

#: a canopen network subscriber: (COB-ID, payload, wire time)
Subscriber = Callable[[int, bytearray, float], None]
#: ``on_image(slot, data, timestamp)``: a process input image TPDO arrived
ImageHandler = Callable[[int, bytearray, float], object]
#: ``on_positions(slots, data, timestamp)``: an encoder default PDO arrived
PositionHandler = Callable[[list[int], bytearray, float], object]
#: a route's handler of one TPDO of the right length: ``(data, timestamp)``
Payload = Callable[[bytearray, float], object]


class FrameListener(GuardedListener):
    """canopen's listener feeding the network wire times, counting every frame on the way.

    A :class:`~ssi_bridge.base.rx_guard.GuardedListener`: a datagram that is not a CAN frame,
    a receive error or a subscriber that raises is counted in the matching
    :class:`ClientCounters` field (``undecodable_frames``, ``receive_errors``,
    ``callback_errors``) of the master and of every ``also`` counter set (the attached
    stations' clients, whose counters the node publishes), logged at most once per second per
    kind, and receiving goes on.

    One listener per frame instead of canopen's plus a separate counter: the notifier calls
    each listener for each frame of the bus. With ``priority`` the notifier's thread, which
    hands every TPDO to its cycle, puts itself on SCHED_FIFO at its first frame and takes the
    kernel name ``ssi_can_rx`` (base/realtime.py); :attr:`scheduling` says what it got.

    :param network: the canopen network the frames are dispatched to
    :param counters: the master's counters
    :param load: the bus-load meter every received frame is queued on (None: none)
    :param priority: SCHED_FIFO priority of the receive thread (0: normal scheduling)
    """

    def __init__(self, network: canopen.Network, counters: ClientCounters,
                 load: BusLoad | None = None, priority: int = 0) -> None:
        super().__init__(network, "master")
        self._counters = counters
        #: further counter sets a fault is counted in (the attached stations' clients)
        self.also: list[ClientCounters] = []
        #: SYNC and NMT frames of other nodes (``client/foreign.py``)
        self.foreign = ForeignTraffic(self.count)
        #: the error frames of the interface, per class (``client/error_frames.py``)
        self.error_frames = ErrorFrameWatch()
        #: queues a received frame on the bus-load meter (``BusLoad.received``), or None
        self._load = load.received if load is not None else None
        self._priority = priority
        #: the receive thread's scheduling ("SCHED_FIFO 5", "normal"; "" before a frame)
        self.scheduling = ""

    def _schedule_this_thread(self) -> None:
        self.scheduling, granted = run_this_thread_at(RX_THREAD_NAME, self._priority)
        if not granted:
            # the cycle thread, refused for the same reason, says it at INFO
            logger.debug("%s runs with normal scheduling: SCHED_FIFO %d not permitted",
                         RX_THREAD_NAME, self._priority)

    def count(self, kind: str) -> None:
        """One fault of ``kind`` (a :class:`ClientCounters` field) in every counter set."""
        super().count(kind)
        for counters in (self._counters, *self.also):
            setattr(counters, kind, getattr(counters, kind) + 1)

    def on_message_received(self, msg: can.Message) -> None:
        """Count ``msg`` (error frames per class too), then dispatch it as
        :class:`~ssi_bridge.base.rx_guard.GuardedListener` does: its route and each
        subscriber on its own, with its wire time (one pass: every frame of the bus
        comes here)."""
        if not self.scheduling:
            self._schedule_this_thread()
        self._counters.frames += 1
        can_id = msg.arbitration_id
        if msg.is_error_frame:
            self._counters.can_errors += 1
            self.error_frames.observe(can_id, msg.data)
        elif self.error_frames.state == BUS_OFF:  # ErrorFrameWatch.bus_off, inline
            self.error_frames.heard(can_id)
        if self._load is not None:
            self._load(msg)
        if msg.is_error_frame or msg.is_remote_frame:
            return  # no service of the master's is a remote or error frame
        data = msg.data
        # base/timebase.frame_wire_time, inline
        wire_t = getattr(msg, "wire_time", 0.0) or msg.timestamp
        if can_id in self.foreign.ids and not msg.is_extended_id:
            # the master hears none of its own frames: another node's SYNC, NMT command, or
            # SDO request to one of its stations
            self.foreign.observe(can_id, data, wire_t)
        if not self._plain_time:  # a subclass's handling time: the guarded listener's way
            GuardedListener.on_message_received(self, msg)
            return
        rule = self.rules.get(can_id)
        if rule is not None and len(data) != rule.length:
            self.malformed(can_id, data, rule.problem(len(data)) or "")
            return
        route = self._routes.get(can_id)
        if route is not None:
            try:
                route(can_id, data, wire_t)
            except Exception as err:  # noqa: BLE001 - as dispatch: counted, receiving goes on
                self._raised(route, can_id, data, err)
        self._dispatch(can_id, data, wire_t)


#: ``on_malformed(can_id, length, expected)``: a TPDO whose length is not its mapping's
MalformedHandler = Callable[[int, int, int], None]
#: bytes of a process image TPDO (000 "Process input": 8 bytes) and of one slot's 0x6820
#: (Integer32) in an encoder default TPDO (000 Table 15)
IMAGE_BYTES, POSITION_BYTES = 8, 4


def _checked(expected: int, handler: Payload, on_malformed: MalformedHandler) -> Subscriber:
    """``handler`` (given the payload and wire time) for frames of ``expected`` bytes; any
    other length goes to ``on_malformed`` and is never decoded (CiA 301: a PDO shorter than
    its mapping is an error; a longer one is no frame this mapping produced)."""
    def route(can_id: int, data: bytearray, timestamp: float) -> None:
        if len(data) == expected:
            handler(data, timestamp)
        else:
            on_malformed(can_id, len(data), expected)
    return route


class TpdoRoutes:
    """The client's handlers on the COB-IDs of the TPDOs it maps (000 Table 15).

    :param node_id: the gateway's node id
    :param slots: modules in the station (TPDO 1..slots carry the images)
    :param on_image: called with the slot for TPDO s
    :param on_positions: called with the slots carried for TPDO 9..12
    :param on_malformed: called instead for a TPDO whose length differs from its mapping
    """

    def __init__(self, node_id: int, slots: int, on_image: ImageHandler,
                 on_positions: PositionHandler,
                 on_malformed: MalformedHandler | None = None) -> None:
        self.routes: dict[int, Subscriber] = {}
        #: PDO number of each route (the RemoteNode's map on the same COB-ID)
        self.pdo_numbers: dict[int, int] = {}
        refuse = on_malformed or (lambda can_id, length, expected: None)
        for slot in range(1, slots + 1):
            self._add(slot, node_id, _checked(IMAGE_BYTES, partial(on_image, slot), refuse))
        for pdo_no, carried in position_pdos(slots):
            self._add(pdo_no, node_id, _checked(POSITION_BYTES * len(carried),
                                                partial(on_positions, carried), refuse))

    def _add(self, pdo_no: int, node_id: int, handler: Subscriber) -> None:
        cob_id = tpdo_cob_base(pdo_no) + node_id
        self.routes[cob_id] = handler
        self.pdo_numbers[cob_id] = pdo_no

    def attach(self, network: canopen.Network) -> None:
        """Route every COB-ID to its handler (once, before the PDOs are configured): straight
        from the listener on the master's network (``OwnListenerNetwork.route``), else as a
        canopen subscriber.

        :param network: the master's canopen network
        """
        for cob_id, handler in self.routes.items():
            if isinstance(network, OwnListenerNetwork):
                network.route(cob_id, handler)
            else:
                network.subscribe(cob_id, handler)

    def release_maps(self, node: canopen.RemoteNode) -> None:
        """Take canopen's PdoMap handlers of ``node`` (the station's RemoteNode) off the
        routed COB-IDs (after ``PdoMap.save``)."""
        network = node.network
        for cob_id, pdo_no in self.pdo_numbers.items():
            handler = pdo_handler(node, pdo_no)
            if handler in subscribers(network, cob_id):
                network.unsubscribe(cob_id, handler)
                logger.debug("TPDO%d 0x%03X: received raw, not through its PdoMap", pdo_no,
                             cob_id)
