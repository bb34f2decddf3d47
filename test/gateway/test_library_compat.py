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
