"""Canaries of the private API of python-can and canopen (base/can_compat.py,
base/canopen_compat.py): a library release that renamed one fails here, by name."""

from __future__ import annotations

import inspect

import can
import canopen

from ssi_bridge.base import can_compat, canopen_compat
from ssi_bridge.base.od import build_dictionary


def test_a_virtual_bus_steps_through_python_cans_own_loop(request):
    channel = f"compat_{request.node.name}"
    with can.Bus(interface="virtual", channel=channel) as rx, \
            can.Bus(interface="virtual", channel=channel) as tx:
        assert can_compat.steps_itself(rx)
        assert can_compat.recv_step(rx, 0.0) is None
        tx.send(can.Message(arbitration_id=0x123, data=b"\x01", is_extended_id=False))
        msg = can_compat.recv_step(rx, 1.0)
        assert msg is not None and msg.arbitration_id == 0x123
        rx.set_filters([{"can_id": 0x7FF, "can_mask": 0x7FF}])
        tx.send(can.Message(arbitration_id=0x124, data=b"", is_extended_id=False))
        assert can_compat.recv_step(rx, 1.0) is None, "a filtered frame is no frame"
        tx.send(can.Message(arbitration_id=0x125, data=b"", is_extended_id=False))
        assert can_compat.recv_step_unfiltered(rx, 1.0).arbitration_id == 0x125
        assert not can_compat.is_shut_down(rx)
    assert can_compat.is_shut_down(rx)


def test_the_periodic_task_hook_has_the_signature_the_wrapper_overrides():
    params = list(inspect.signature(can.BusABC._send_periodic_internal).parameters)
    assert params[:6] == ["self", "msgs", "period", "duration", "autostart",
                          "modifier_callback"], params


def test_the_udp_multicast_internals_are_there():
    assert issubclass(can_compat.UdpMulticastBus, can.BusABC)
    assert isinstance(can_compat.SO_TIMESTAMPNS, int)
    assert callable(can_compat.unpack_message)
    frame = can.Message(arbitration_id=0x181, data=b"\x01", is_extended_id=False)
    assert can_compat.unpack_message(can_compat.pack_message(frame)).equals(frame)
    assert hasattr(can_compat.GeneralPurposeUdpMulticastBus, "recv")


def test_canopens_subscribers_and_the_pdo_handler():
    network = canopen.Network()
    node = canopen.RemoteNode(5, build_dictionary(5, 1))
    network.add_node(node)

    def callback(*_args):
        return None
    network.subscribe(0x185, callback)
    assert callback in canopen_compat.subscribers(network, 0x185)
    assert canopen_compat.subscribers(network, 0x186) == []
    handler = canopen_compat.pdo_handler(node, 1)
    assert callable(handler)


def test_every_sdo_channel_of_the_checked_node_is_a_checked_client():
    """``CheckedRemoteNode``: ``RemoteNode.__init__`` makes its default channel through
    ``add_sdo`` before the PDO maps bind their records to it; the network subscribes it on
    0x580 + id; its transfers run through ``request_response`` / ``read_response`` on the
    ``responses`` queue (the overridden methods: a renamed one would bypass the check;
    test/client/test_sdo_stale_answers.py shows the behaviour)."""
    made: list[object] = []

    class Judge:
        def __init__(self) -> None:
            made.append(self)

        def sent(self, request: bytes) -> None:
            return None

        def why_stale(self, response: bytes) -> str | None:
            return "test"

    node = canopen_compat.CheckedRemoteNode(5, build_dictionary(5, 1), timeout=0.2,
                                            judge=Judge, on_stale=lambda f, why: None)
    checked = node.sdo
    assert isinstance(checked, canopen_compat.CheckedSdoClient)
    assert node.sdo_channels == [checked] and checked.judge is made[0]
    assert (checked.rx_cobid, checked.tx_cobid) == (0x605, 0x585)
    assert (checked.RESPONSE_TIMEOUT, checked.MAX_RETRIES) == (0.1, 2)
    assert node.tpdo[1].com_record.sdo_node is checked
    assert node.rpdo[1].map_array.sdo_node is checked
    network = canopen.Network()
    network.add_node(node)
    assert checked.on_response in canopen_compat.subscribers(network, 0x585)
    for stream in (canopen.sdo.client.ReadableStream, canopen.sdo.client.WritableStream):
        assert "request_response" in inspect.getsource(stream)
    assert "read_response" in inspect.getsource(canopen.sdo.SdoClient.request_response)
    checked.on_response(0x585, b"\x43\x17\x10\x00\x32\x00\x00\x00", 0.0)
    assert checked.responses.qsize() == 1


def test_an_eds_default_is_exported_as_set(tmp_path):
    """``set_eds_default``: canopen's EDS export writes ``default_raw`` as the DefaultValue
    (the COB-IDs relative to the node id, CiA 306 ``$NODEID``), and its import reads it back."""
    dictionary = canopen.ObjectDictionary()
    var = canopen.objectdictionary.ODVariable("COB-ID EMCY", 0x1014, 0)
    var.data_type = canopen.objectdictionary.UNSIGNED32
    var.access_type = "ro"
    var.default = 0x85
    canopen_compat.set_eds_default(var, "$NODEID+0x80")
    dictionary.add_object(var)
    path = tmp_path / "one.eds"
    with open(path, "w", encoding="ascii") as fh:
        canopen.objectdictionary.eds.export_eds(dictionary, fh)
    assert "DefaultValue=$NODEID+0x80" in path.read_text(encoding="ascii")
    assert canopen.import_od(str(path), node_id=7)[0x1014].default == 0x87
