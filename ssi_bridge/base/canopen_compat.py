"""Every use of canopen's private API in one place (canopen 2.4), checked by a canary.

* :func:`subscribers`: the callbacks ``Network.subscribe`` registered for a COB-ID
  (``Network.subscribers``): the guarded listener calls each on its own, and the master takes
  canopen's own PDO handlers off the COB-IDs it routes itself;
* :func:`pdo_handler`: the handler a ``PdoMap`` subscribes when it is saved
  (``PdoMap.on_message``);
* :func:`set_eds_default`: the text an exported EDS gives as a variable's DefaultValue
  (``ODVariable.default_raw``, which canopen's EDS import sets and its export reads, undeclared);
* :class:`CheckedSdoClient`: canopen's ``SdoClient`` that sets its retry attributes
  (``RESPONSE_TIMEOUT``, ``MAX_RETRIES``, ``PAUSE_BEFORE_SEND``) and overrides the two methods
  its transfer streams wait through (``request_response``, ``read_response``, reading the
  ``responses`` queue ``on_response`` fills), so that a frame which does not answer the
  current request is set aside instead of ending the transfer; :class:`CheckedRemoteNode`
  makes its SDO channels such clients (``add_sdo``, which ``RemoteNode.__init__`` calls
  before it binds the PDO maps to the default channel);
* :class:`OwnListenerNetwork`: the one canopen ``Network`` of the master (``client/bus.py``)
  and of the simulated gateway (``sim/gateway/bus.py``): its owner's listener in place of
  canopen's ``MessageListener`` (``Network.listeners``), its notifier's wake-up period
  (``NOTIFIER_CYCLE``), no re-raise of a handled receive error (``Network.check``, which reads
  ``notifier.exception``), and ``send_message`` returning the frame it sent;
* :func:`dispatcher`: canopen's ``Network.notify`` with each subscriber called on its own
  (``Network.subscribers``, changed in place by ``subscribe``, and the node scanner's
  ``on_message_received(can_id)``, whose argument differs between canopen's upstream lines),
  for ``base/rx_guard.py``;
* :func:`forget_receive_error`: clears a handled receive error from the notifier canopen's
  ``check`` reads (``Notifier.exception``), for a plain ``canopen.Network``;
* :func:`drop_node`: takes a node out of a network's node table (``Network.nodes``) and
  nothing else;
* :func:`forget_values`: drops what was written to a ``LocalNode`` (``LocalNode.data_store``),
  so its objects read their defaults again.

``test/base/test_library_compat.py`` fails on a canopen whose private names changed.
"""

from __future__ import annotations

import queue
import time
from collections.abc import Callable
from typing import Protocol

import can
import canopen
from canopen.objectdictionary import ODVariable
from canopen.sdo.client import SdoClient
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError


#: a callback canopen's network calls for a frame: (COB-ID, data, timestamp)
Subscriber = Callable[[int, bytearray, float], None]


def subscribers(network: canopen.Network, can_id: int) -> list[Subscriber]:
    """The callbacks subscribed to ``can_id`` (the network's own list: do not change it)."""
    found: list[Subscriber] = network.subscribers.get(can_id, [])
    return found


def set_eds_default(var: ODVariable, text: str) -> None:
    """Export ``var`` with DefaultValue ``text`` (e.g. ``$NODEID+0x180``) in an EDS."""
    var.default_raw = text  # type: ignore[attr-defined]  # undeclared in canopen


def pdo_handler(node: canopen.RemoteNode, tpdo: int) -> Subscriber:
    """The handler TPDO ``tpdo`` of ``node`` subscribes to its COB-ID when saved."""
    handler: Subscriber = node.tpdo[tpdo].on_message
    return handler


class AnswerJudge(Protocol):
    """Tells the answer to the current SDO request from a stale frame
    (``client/sdo_answers.py`` ``SdoAnswers``)."""

    def sent(self, request: bytes) -> None:
        """``request`` is the one the next answer must answer."""

    def why_stale(self, response: bytes) -> str | None:
        """None when ``response`` may answer the current request; else why it cannot."""


#: what a set-aside frame is reported to: (the frame, why it answers no current request)
OnStale = Callable[[bytes, str], None]
#: command specifier of a server's abort (CiA 301: bits 7-5 of byte 0 = 4)
_ABORT = 4 << 5


class CheckedSdoClient(SdoClient):
    """canopen's SDO client that takes only the answer to its current request.

    Each wait for an answer (``read_response``, one attempt) lasts up to ``timeout / 2``; a
    request gets one repeat after a lost frame (canopen counts the first attempt as a retry:
    ``MAX_RETRIES = 2``), so a transfer step is bounded by ``timeout``. A frame ``judge`` finds
    stale, and a frame that arrived while no request was outstanding, goes to ``on_stale``
    and the wait goes on within the same deadline; an abort that answers the current request
    raises ``SdoAbortedError``, no answer in time ``SdoCommunicationError``, as canopen's own.
    """

    def __init__(self, rx_cobid: int, tx_cobid: int, od: canopen.ObjectDictionary, *,
                 timeout: float, judge: AnswerJudge, on_stale: OnStale) -> None:
        super().__init__(rx_cobid, tx_cobid, od)  # type: ignore[no-untyped-call]
        self.RESPONSE_TIMEOUT = timeout / 2
        self.MAX_RETRIES = 2
        self.PAUSE_BEFORE_SEND = 0.0
        self.judge = judge
        self.on_stale = on_stale
        self._awaiting = False

    def request_response(self, sdo_request: bytes | bytearray) -> bytes:
        """Set aside what arrived since the last answer, send ``sdo_request`` (again after a
        timeout) and return its answer (raises SdoAbortedError, SdoCommunicationError)."""
        while True:
            try:
                left = self.responses.get_nowait()
            except queue.Empty:
                break
            self.on_stale(left, "it arrived while no request was outstanding")
        self.judge.sent(bytes(sdo_request))
        self._awaiting = True
        try:
            return bytes(super().request_response(sdo_request))  # type: ignore[no-untyped-call]
        finally:
            self._awaiting = False

    def read_response(self) -> bytes:
        """The next frame that answers the current request, within ``RESPONSE_TIMEOUT``
        (raises SdoAbortedError for its abort, SdoCommunicationError when none came)."""
        deadline = time.monotonic() + self.RESPONSE_TIMEOUT
        while True:
            try:
                response = bytes(self.responses.get(
                    timeout=max(0.0, deadline - time.monotonic())))
            except queue.Empty:
                raise SdoCommunicationError("No SDO response received") from None
            why = self.judge.why_stale(response) if self._awaiting else None
            if why is None:
                break
            self.on_stale(response, why)
        if response and response[0] & 0xE0 == _ABORT:
            raise SdoAbortedError(int.from_bytes(response[4:8], "little"))
        return response


class CheckedRemoteNode(canopen.RemoteNode):
    """A ``RemoteNode`` whose SDO channels are checked SDO clients (:class:`CheckedSdoClient`).

    ``RemoteNode.__init__`` makes its default channel (0x600 + id / 0x580 + id) through
    ``add_sdo`` before its PDO maps bind their communication and mapping records to that
    client, so every SDO transfer of the node, the PDO set-up's too, is checked.

    :param node_id: the remote node's id (1-127)
    :param dictionary: its object dictionary
    :param timeout: the SDO response timeout (s) of each channel
    :param judge: makes the judge of one channel (called once per channel)
    :param on_stale: told of every frame set aside, on the thread that waited for an answer
    """

    def __init__(self, node_id: int, dictionary: canopen.ObjectDictionary, *, timeout: float,
                 judge: Callable[[], AnswerJudge], on_stale: OnStale) -> None:
        self._sdo_timeout = timeout
        self._judge = judge
        self._on_stale = on_stale
        super().__init__(node_id, dictionary)

    def add_sdo(self, rx_cobid: int, tx_cobid: int) -> CheckedSdoClient:
        """An SDO channel to the server on ``rx_cobid`` answering on ``tx_cobid``."""
        client = CheckedSdoClient(rx_cobid, tx_cobid, self.object_dictionary,
                                  timeout=self._sdo_timeout, judge=self._judge(),
                                  on_stale=self._on_stale)
        self.sdo_channels.append(client)
        if self.has_network():
            self.network.subscribe(client.tx_cobid, client.on_response)
        return client


#: a subscriber that raised, the frame's COB-ID and data, and what it raised (:func:`dispatcher`)
OnRaise = Callable[[Callable[..., object], int, bytearray, Exception], None]


#: canopen's ``Network.notify`` for one frame of a network (:func:`dispatcher`)
Dispatch = Callable[[int, bytearray, float], None]


def dispatcher(network: canopen.Network, on_raise: OnRaise) -> Dispatch:
    """canopen's ``Network.notify`` for ``network``, each subscriber called on its own: one
    that raises goes to ``on_raise`` (with the frame and its exception) and the others still
    get the frame; then the network's node scanner notes the COB-ID, unless it lists the
    frame's node already (its ``on_message_received`` would change nothing).

    Prepared once, called per frame ``(can_id, data, timestamp)`` (the time handed to every
    subscriber; the master's: its wire time): it holds the network's subscriber table, which
    ``subscribe``/``unsubscribe`` change in place, and its scanner, whose ``nodes`` it reads
    at every frame (``reset`` replaces the list).
    """
    subscribed = network.subscribers.get
    scanner = network.scanner
    scan = scanner.on_message_received

    def notify(can_id: int, data: bytearray, timestamp: float) -> None:
        callbacks = subscribed(can_id)
        if callbacks:
            for callback in callbacks:  # as canopen's notify
                try:
                    callback(can_id, data, timestamp)
                except Exception as err:  # noqa: BLE001 - one must not stop the others
                    on_raise(callback, can_id, data, err)
        if can_id & 0x7F not in scanner.nodes:
            scan(can_id)
    return notify


def forget_receive_error(network: canopen.Network, exc: BaseException) -> None:
    """``exc``, a receive error a listener handled, is not raised by ``network.check()`` at
    the next send (canopen raises the notifier's last exception there)."""
    notifier = network.notifier
    if notifier is not None and notifier.exception is exc:
        notifier.exception = None


def drop_node(network: canopen.Network, node_id: int) -> None:
    """Take node ``node_id`` (if there) out of ``network``'s node table, leaving its
    subscriptions as they are (unlike ``del network[node_id]``)."""
    network.nodes.pop(node_id, None)


def forget_values(node: canopen.LocalNode, index: Callable[[int], bool] | None = None) -> None:
    """Forget the values written to ``node``'s objects (those whose index ``index`` accepts;
    None: all), so they read their dictionary defaults again."""
    store = node.data_store
    if index is None:
        store.clear()
        return
    for stored in [i for i in store if index(i)]:
        del store[stored]


class OwnListenerNetwork(canopen.Network):
    """canopen's ``Network`` with one listener of its owner's and a hook on every frame sent.

    :meth:`start` connects it with ``listener`` as the only listener of its notifier, in place
    of canopen's ``MessageListener`` (which calls ``notify`` unguarded: a subscriber that
    raises stops the others); that listener handles every receive error, so :meth:`check`
    has nothing to raise. ``send_message`` is canopen's documented hook for a custom back
    end: everything canopen sends (NMT, SYNC, SDO, EMCY, PDOs) goes out through it
    unchanged, under the same lock, is handed to :attr:`on_sent` and returned, so a caller
    can read its timestamp (on a simulated wire its end on the wire). A subclass makes its
    own frames (:meth:`make_frame`).

    :param bus: the bus (None: connect opens one)
    :param notifier_cycle: the receive thread's wake-up period (s), which bounds how long
        stopping the network takes (None: canopen's)
    """

    #: called with every frame :meth:`send_message` sent (the bus load)
    on_sent: Callable[[can.Message], None] | None = None

    def __init__(self, bus: can.BusABC | None = None, *,
                 notifier_cycle: float | None = None) -> None:
        super().__init__(bus)
        if notifier_cycle is not None:
            self.NOTIFIER_CYCLE = notifier_cycle
        #: COB-ID -> the one handler its owner routes it to (:meth:`route`)
        self.routes: dict[int, Subscriber] = {}
        #: started with canopen's ``MessageListener`` too: routes become subscriptions
        self._canopens_listener = False

    def route(self, can_id: int, handler: Subscriber) -> None:
        """Hand every frame of ``can_id`` to ``handler`` straight from the listener
        (``base/rx_guard.GuardedListener``), before the subscribers canopen keeps for it
        (normally none): a TPDO the owner decodes itself skips canopen's subscriber walk.
        A later route of the same COB-ID replaces this one. On a network started with
        canopen's own listener too (``start(canopens_too=True)``), which knows no routes, the
        handler is subscribed instead."""
        if self._canopens_listener:
            self.subscribe(can_id, handler)
        else:
            self.routes[can_id] = handler

    def start(self, *listeners: can.Listener, canopens_too: bool = False) -> None:
        """Connect with ``listeners`` as the network's listeners, after canopen's own
        ``MessageListener`` when ``canopens_too`` (raises what ``Network.connect`` raises)."""
        own: list[can.Listener] = list(self.listeners[:1]) if canopens_too else []
        self._canopens_listener = canopens_too
        if canopens_too:  # canopen's listener calls subscribers only
            for can_id, handler in self.routes.items():
                self.subscribe(can_id, handler)
            self.routes.clear()
        self.listeners[:] = [*own, *listeners]  # type: ignore[list-item]  # canopen: its own
        self.connect()

    def check(self) -> None:
        """Nothing to check: the owner's listener (``base/rx_guard.GuardedListener``) handles
        every receive error and keeps receiving, so none is left to raise."""

    def make_frame(self, can_id: int, data: bytes, remote: bool) -> can.Message:
        """The frame :meth:`send_message` sends: a ``can.Message`` as canopen makes it.

        :param can_id: the CAN identifier (above 0x7FF: an extended one)
        :param data: the payload (0-8 bytes)
        :param remote: a remote transmission request
        """
        return can.Message(arbitration_id=can_id, is_extended_id=can_id > 0x7FF, data=data,
                           is_remote_frame=remote)

    # canopen declares the hook -> None; returning the frame adds to that (canopen's own
    # callers ignore the value), which mypy counts as an incompatible override
    def send_message(  # type: ignore[override]
            self, can_id: int, data: bytes, remote: bool = False) -> can.Message:
        """Send one frame and return it (raises ``can.CanError``, RuntimeError when not
        connected).

        :param can_id: the CAN identifier
        :param data: the payload (0-8 bytes)
        :param remote: a remote transmission request
        :returns: the frame sent (on a simulated wire its timestamp is its end on the wire)
        """
        return self.send_frame(self.make_frame(can_id, data, remote))

    def send_frame(self, frame: can.Message) -> can.Message:
        """Send ``frame`` as :meth:`send_message` sends the one it makes (under the same lock,
        handed to :attr:`on_sent`) and return it: for a caller that sends the same frame
        again (raises ``can.CanError``, RuntimeError when not connected).

        :param frame: a frame as :meth:`make_frame` makes it
        """
        if not self.bus:
            raise RuntimeError("Not connected to CAN bus")
        with self.send_lock:
            self.bus.send(frame)
        if self.on_sent is not None:
            self.on_sent(frame)
        return frame


__all__ = ["AnswerJudge", "CheckedRemoteNode", "CheckedSdoClient", "Dispatch", "OnRaise",
           "OwnListenerNetwork", "dispatcher", "drop_node", "forget_receive_error",
           "forget_values", "pdo_handler", "set_eds_default", "subscribers"]
