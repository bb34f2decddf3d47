"""Canaries of the canopen internals behind the one network class of the master and the
simulated gateway (base/canopen_compat.py ``OwnListenerNetwork``, ``dispatcher``,
``forget_receive_error``, ``drop_node``, ``forget_values``): a canopen release that changed
one fails here, by name, on a real canopen ``Network`` on python-can's virtual bus."""

from __future__ import annotations

import inspect
from typing import Any

import can
import canopen
import pytest

from ssi_bridge.base.canopen_compat import (
    OwnListenerNetwork, dispatcher, drop_node, forget_receive_error, forget_values, subscribers,
)
from support.waiting import wait_for


class _Heard(can.Listener):
    """Keeps every frame it is given."""

    def __init__(self) -> None:
        self.frames: list[can.Message] = []

    def on_message_received(self, msg: can.Message) -> None:
        self.frames.append(msg)


def test_start_puts_the_owners_listener_in_place_of_canopens(request) -> None:
    """``Network.listeners`` is the list ``connect`` hands to the notifier, and its first
    entry is canopen's ``MessageListener`` (kept with ``canopens_too``); ``NOTIFIER_CYCLE``
    is the notifier's wake-up period."""
    channel = f"net_{request.node.name}"
    assert isinstance(canopen.Network().listeners[0], canopen.network.MessageListener)
    assert "self.listeners, self.NOTIFIER_CYCLE" in inspect.getsource(canopen.Network.connect)
    mine = _Heard()
    network = OwnListenerNetwork(can.Bus(interface="virtual", channel=channel),
                                 notifier_cycle=0.05)
    network.start(mine)
    try:
        assert network.notifier is not None and network.notifier.listeners == [mine]
        assert network.notifier.timeout == 0.05
        with can.Bus(interface="virtual", channel=channel) as peer:
            peer.send(can.Message(arbitration_id=0x701, data=b"\x05", is_extended_id=False))
            wait_for(lambda: len(mine.frames) == 1,
                     "the owner's listener did not hear exactly the one frame within 2 s",
                     timeout=2.0, poll=0.005)
    finally:
        network.disconnect()
    both = OwnListenerNetwork(can.Bus(interface="virtual", channel=channel))
    both.start(mine, canopens_too=True)
    try:
        assert both.notifier is not None
        assert [type(x) for x in both.notifier.listeners] == [canopen.network.MessageListener,
                                                              _Heard]
        assert both.notifier.timeout == canopen.Network.NOTIFIER_CYCLE
    finally:
        both.disconnect()


def test_a_handled_receive_error_is_not_raised_at_the_next_send(request) -> None:
    """canopen's ``check`` raises the notifier's ``exception`` at a send (so a plain network
    must forget a handled one, ``forget_receive_error``); the own network never raises it."""
    channel = f"net_{request.node.name}"
    err = can.CanOperationError("interface down")
    plain = canopen.Network()
    plain.connect(interface="virtual", channel=channel)
    own = OwnListenerNetwork(can.Bus(interface="virtual", channel=channel))
    own.start(_Heard())
    try:
        for network in (plain, own):
            assert network.notifier is not None
            network.notifier.exception = err
        with pytest.raises(can.CanOperationError):
            plain.send_message(0x80, b"")
        forget_receive_error(plain, can.CanOperationError("another"))
        with pytest.raises(can.CanOperationError):
            plain.check()
        forget_receive_error(plain, err)
        plain.send_message(0x80, b"")
        own.check()
        sent: list[can.Message] = []
        own.on_sent = sent.append
        frame = own.send_message(0x80, b"")
        assert sent == [frame] and frame.arbitration_id == 0x80 and not frame.is_extended_id
    finally:
        plain.disconnect()
        own.notifier.exception = None  # type: ignore[union-attr]
        own.disconnect()


def test_an_unconnected_network_refuses_to_send() -> None:
    with pytest.raises(RuntimeError, match="Not connected"):
        OwnListenerNetwork().send_message(0x80, b"")


def test_the_send_hook_is_the_one_canopen_sends_through() -> None:
    """``send_message(can_id, data, remote)`` is the hook canopen's services send through
    (the SDO client, NMT, SYNC); an override of another signature would not be called."""
    assert list(inspect.signature(canopen.Network.send_message).parameters) == [
        "self", "can_id", "data", "remote"]
    assert "network.send_message(" in inspect.getsource(canopen.sdo.client.SdoClient)
    assert "network.send_message(" in inspect.getsource(canopen.nmt.NmtMaster)
    assert "send_message(" in inspect.getsource(canopen.sync.SyncProducer.transmit)


def test_the_dispatcher_is_canopens_notify_with_each_subscriber_on_its_own() -> None:
    """canopen's ``notify`` calls ``subscribers[can_id]`` in order and then the node scanner's
    ``on_message_received(can_id)`` (a COB-ID: canopen's other upstream line passes a
    different argument); the ``dispatcher`` does the same, and a subscriber that raises is
    handed to ``on_raise`` while the next one still gets the frame. It is made once per
    network: ``subscribe`` and ``unsubscribe`` change the table it holds in place, and a
    scanner ``reset`` (a new ``nodes`` list) is seen at the next frame."""
    source = inspect.getsource(canopen.Network.notify)
    assert "self.subscribers[can_id]" in source
    assert "callback(can_id, data, timestamp)" in source
    assert "self.scanner.on_message_received(can_id)" in source
    assert list(inspect.signature(canopen.network.NodeScanner.on_message_received)
                .parameters) == ["self", "can_id"]
    assert "self.nodes = []" in inspect.getsource(canopen.network.NodeScanner.reset)
    network = canopen.Network()
    got: list[tuple[int, bytes, float]] = []
    raised: list[tuple[Any, int, bytes, Exception]] = []

    def breaks(can_id: int, data: bytearray, t: float) -> None:
        raise ValueError("cannot parse")

    def keeps(can_id: int, data: bytearray, t: float) -> None:
        got.append((can_id, bytes(data), t))

    notify = dispatcher(network, lambda cb, can_id, data, err: raised.append(
        (cb, can_id, bytes(data), err)))
    network.subscribe(0x185, breaks)
    network.subscribe(0x185, keeps)
    assert subscribers(network, 0x185) == [breaks, keeps]
    notify(0x185, bytearray(b"\x01\x02"), 12.5)
    assert got == [(0x185, b"\x01\x02", 12.5)]
    assert [(cb, can_id, data) for cb, can_id, data, _ in raised] == [
        (breaks, 0x185, b"\x01\x02")]
    assert isinstance(raised[0][3], ValueError)
    assert network.scanner.nodes == [5], "a TPDO1 of node 5 is seen by the scanner"
    notify(0x186, bytearray(), 0.0)
    notify(0x286, bytearray(), 0.0)
    assert network.scanner.nodes == [5, 6]
    network.unsubscribe(0x185, keeps)
    notify(0x185, bytearray(b"\x03"), 13.0)
    assert got == [(0x185, b"\x01\x02", 12.5)] and len(raised) == 2
    network.scanner.reset()
    notify(0x706, bytearray(b"\x05"), 14.0)
    assert network.scanner.nodes == [6], "found again after a reset"


def test_a_dropped_node_leaves_the_table_and_keeps_its_subscriptions() -> None:
    """``drop_node``: ``Network.nodes`` is the table ``network[node_id]`` reads; dropping
    leaves the node's SDO subscription (``del network[id]`` would remove it too)."""
    from ssi_bridge.base.od import build_dictionary
    network = canopen.Network()
    node = canopen.RemoteNode(5, build_dictionary(5, 1))
    network.add_node(node)
    assert network[5] is node
    drop_node(network, 5)
    drop_node(network, 5)  # not there: nothing to do
    assert 5 not in network
    assert node.sdo.on_response in subscribers(network, 0x585)


def test_forgotten_values_read_their_defaults_again() -> None:
    """``forget_values``: ``LocalNode.data_store`` holds what was written (index ->
    subindex -> bytes); without it an object reads its dictionary default."""
    from ssi_bridge.base.od import build_dictionary
    node = canopen.LocalNode(5, build_dictionary(5, 1))
    default = node.get_data(0x1800, 5, check_readable=False)
    node.set_data(0x1014, 0, b"\x85\x00\x00\x00", check_writable=False)
    node.set_data(0x1800, 5, b"\x64\x00", check_writable=False)
    assert node.data_store[0x1014] == {0: b"\x85\x00\x00\x00"}
    forget_values(node, lambda index: index == 0x1014)
    assert node.get_data(0x1800, 5, check_readable=False) == b"\x64\x00"
    assert 0x1014 not in node.data_store
    forget_values(node)
    assert node.data_store == {}
    assert node.get_data(0x1800, 5, check_readable=False) == default != b"\x64\x00"


def test_a_routed_frame_goes_straight_to_its_handler_and_a_raising_route_is_counted() -> None:
    """``OwnListenerNetwork.route`` with the guarded listener: the routed COB-ID's handler
    gets the frame with its wire time, a canopen subscriber of the same COB-ID still gets
    it, a route that raises is a counted callback error (receiving goes on), the node
    scanner notes the frame, and a frame of the wrong length for its rule reaches nobody."""
    from ssi_bridge.base.rx_guard import CALLBACK_ERROR, MALFORMED, GuardedListener
    from ssi_bridge.protocol.frame_rules import FrameRule

    network = OwnListenerNetwork(None)
    listener = GuardedListener(network)
    routed: list[tuple[int, bytes, float]] = []
    subscribed: list[int] = []
    network.route(0x185, lambda can_id, data, t: routed.append((can_id, bytes(data), t)))
    network.subscribe(0x185, lambda can_id, data, t: subscribed.append(can_id))

    def breaks(can_id: int, data: bytearray, t: float) -> None:
        raise ValueError("cannot parse")

    network.route(0x186, breaks)
    frame = can.Message(arbitration_id=0x185, data=b"\x01\x02", is_extended_id=False,
                        timestamp=12.5)
    listener.on_message_received(frame)
    assert routed == [(0x185, b"\x01\x02", 12.5)] and subscribed == [0x185]
    assert network.scanner.nodes == [5]
    listener.on_message_received(can.Message(arbitration_id=0x186, data=b"\x03",
                                             is_extended_id=False, timestamp=13.0))
    assert listener.faults[CALLBACK_ERROR] == 1 and network.scanner.nodes == [5, 6]
    listener.rules[0x185] = FrameRule("TPDO1 of node 5", 8)
    listener.on_message_received(frame)
    assert len(routed) == 1 and listener.faults[MALFORMED] == 1


def test_routes_become_subscriptions_where_canopens_listener_dispatches(request) -> None:
    """A network started with canopen's own ``MessageListener`` (``canopens_too``) knows no
    routes: a route given before or after the start is subscribed instead."""
    network = OwnListenerNetwork(can.Bus(interface="virtual", channel=f"net_{request.node.name}"))
    before, after = (lambda *a: None), (lambda *a: None)
    network.route(0x181, before)
    network.start(canopens_too=True)
    try:
        network.route(0x182, after)
        assert network.routes == {}
        assert subscribers(network, 0x181) == [before]
        assert subscribers(network, 0x182) == [after]
    finally:
        network.disconnect()
