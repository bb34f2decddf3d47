"""One master per bus: what only a master sends (SYNC, NMT, SDO requests to its stations) is
heard before the node's first frame, and seen while it runs.

Frames come from a second python-can bus of the test on the same virtual channel (another
node). A TPDO or an SDO request to a station of someone else is no master's frame for us.
"""

from __future__ import annotations

import time

import can
import pytest

from ssi_bridge.client.foreign import master_frames
from ssi_bridge.client.one_master import ensure_alone, heard_masters
from ssi_bridge.exceptions import BusError
from ssi_bridge.protocol.settings import BusConfig


def _frame(can_id: int, data: bytes = b"") -> can.Message:
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False)


def test_the_frames_only_a_master_sends() -> None:
    frames = master_frames([1, 3])
    assert set(frames) == {0x080, 0x000, 0x601, 0x603}


def test_another_master_is_heard_and_named_before_the_first_frame(channel: str) -> None:
    listener = can.Bus(interface="virtual", channel=channel)
    other = can.Bus(interface="virtual", channel=channel)
    try:
        for frame in (_frame(0x080), _frame(0x000, b"\x80\x01"), _frame(0x601, bytes(8)),
                      _frame(0x609, bytes(8)), _frame(0x181, bytes(8)), _frame(0x701, b"\x05")):
            other.send(frame)
        heard = heard_masters(listener, [1], 0.2)
    finally:
        listener.shutdown()
        other.shutdown()
    assert heard == {"SYNC on 0x080": 1,
                     "NMT enter PRE-OPERATIONAL (0x80) to node 1 on 0x000": 1,
                     "SDO request to node 1 on 0x601": 1}, heard


def test_ensure_alone_refuses_a_bus_another_master_syncs(channel: str) -> None:
    """On an interface another process can reach (here socketcan's name, opened on the test's
    virtual channel): quiet, nothing happens; another master's SYNC is a BusError naming it."""
    other = can.Bus(interface="virtual", channel=channel)
    config = BusConfig(interface="socketcan", channel=channel)

    def quiet(cfg: BusConfig) -> can.BusABC:
        return can.Bus(interface="virtual", channel=channel)

    def open_while_the_other_syncs(cfg: BusConfig) -> can.BusABC:
        bus = can.Bus(interface="virtual", channel=channel)
        other.send(_frame(0x080))  # the other master's SYNC, heard by the bus just opened
        return bus
    try:
        ensure_alone(config, [1], opener=quiet, window=0.1)
        with pytest.raises(BusError, match=r"another CANopen master drives socketcan:.* 1 x "
                                           r"SYNC on 0x080.*one master per bus"):
            ensure_alone(config, [1], opener=open_while_the_other_syncs, window=0.1)
        # a listen-only observer, and the process's own virtual bus, are not checked
        ensure_alone(config, [1], opener=open_while_the_other_syncs, window=0.1,
                     listen_only=True)
        ensure_alone(BusConfig(interface="virtual", channel=channel), [1],
                     opener=open_while_the_other_syncs, window=0.1)
    finally:
        other.shutdown()


def test_a_bus_that_cannot_be_opened_is_left_to_its_next_opener() -> None:
    def broken(cfg: BusConfig) -> can.BusABC:
        raise BusError("cannot open CAN bus")
    ensure_alone(BusConfig(interface="virtual", channel="x"), [1], opener=broken, window=0.1)


def test_a_running_master_counts_sdo_requests_to_its_station_it_did_not_send(
        station, channel: str) -> None:
    _gateway, client, _readers = station
    sender = can.Bus(interface="virtual", channel=channel)
    try:  # an SDO upload request of 0x1000:00 from another SDO client
        sender.send(_frame(0x600 + client.node_id, bytes([0x40, 0x00, 0x10, 0, 0, 0, 0, 0])))
        deadline = time.monotonic() + 2.0
        while client.counters.foreign_station_frames < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        sender.shutdown()
    assert client.counters.foreign_station_frames == 1
    assert "SDO request to node 5 on 0x605 not sent by this master" in \
        client.master.foreign_traffic(5.0)
