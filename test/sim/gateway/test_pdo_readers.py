"""TPDO payloads on the per-mapping readers equal what SDO (LocalNode.get_data) reads.

The station encodes 0x2000:s and 0x6820:s for its TPDOs directly and every other mapped
object through canopen's ``get_data``; both must put the same bytes on the bus as an SDO
upload of the same objects right after the cycle. Plus the frames of ``BridgeNetwork``.
"""

from __future__ import annotations

import copy

import can
import canopen

from ssi_bridge.sim.gateway.bus import BridgeNetwork, WireMessage
from ssi_bridge.protocol.dictionary import tpdo_cob_base
from ssi_bridge.protocol.registers import PARA1_DEFAULT

from .conftest import NODE_ID

ERR_PARA, STS_STOP = 0x10, 0x80


def _map(node: canopen.RemoteNode, number: int,
         entries: list[tuple[int, int]]) -> canopen.pdo.PdoMap:
    pdo = node.tpdo[number]
    pdo.clear()
    for index, subindex in entries:
        pdo.add_variable(index, subindex)
    pdo.cob_id, pdo.trans_type, pdo.enabled = tpdo_cob_base(number) + NODE_ID, 1, True
    pdo.save()
    return pdo


def _received_after_sync(st, maps: list[canopen.pdo.PdoMap]) -> list[bytes]:
    for m in maps:
        m.is_received = False
    st.sync()
    st.wait_for(lambda: all(m.is_received for m in maps), "not every mapped TPDO arrived")
    return [bytes(m.data) for m in maps]


def _sdo_bytes(st, entries: list[tuple[int, int]]) -> bytes:
    return b"".join(st.node.sdo.upload(index, subindex) for index, subindex in entries)


def test_direct_and_generic_readers_send_the_sdo_bytes(station) -> None:
    st = station
    st.node.sdo[0x6810][1].raw = -5000  # REG_OFFSET 5000 above the value: negative Integer32
    layouts = [
        [(0x2000, 1)],
        [(0x6820, 1), (0x6820, 2)],
        [(0x6820, 2), (0x5805, 1), (0x5802, 1), (0x6C00, 2)],  # mixed direct + get_data
        [(0x6810, 1), (0x6B00, 2)],  # generic only
    ]
    maps = [_map(st.node, n + 1, entries) for n, entries in enumerate(layouts)]
    st.node.nmt.state = "OPERATIONAL"
    st.wait_for(lambda: st.gateway.nmt_state == "OPERATIONAL", "gateway not OPERATIONAL")
    for value in (1000, 1100, 0xFFFFFF):
        st.readers[0].value = value
        payloads = _received_after_sync(st, maps)
        for entries, payload in zip(layouts, payloads):
            assert payload == _sdo_bytes(st, entries), f"{entries}: TPDO differs from SDO"
        position = int.from_bytes(payloads[1][:4], "little", signed=True)
        assert position == value - 5000


def test_remapping_switches_the_reader(station) -> None:
    st = station
    pdo = _map(st.node, 1, [(0x2000, 1)])
    st.node.nmt.state = "OPERATIONAL"
    st.wait_for(lambda: st.gateway.nmt_state == "OPERATIONAL", "gateway not OPERATIONAL")
    assert len(_received_after_sync(st, [pdo])[0]) == 8
    st.node.nmt.state = "PRE-OPERATIONAL"
    st.wait_for(lambda: st.gateway.nmt_state == "PRE-OPERATIONAL", "gateway not PRE-OP")
    pdo = _map(st.node, 1, [(0x6820, 2)])
    st.node.nmt.state = "OPERATIONAL"
    st.wait_for(lambda: st.gateway.nmt_state == "OPERATIONAL", "gateway not OPERATIONAL")
    payload = _received_after_sync(st, [pdo])[0]
    assert payload == (2000).to_bytes(4, "little"), "TPDO1 still sends the old mapping"


def test_input_image_shows_a_rejected_parameter_set_before_the_next_cycle(station) -> None:
    st = station
    st.sync()
    assert not st.node.sdo.upload(0x2000, 1)[7] & (ERR_PARA | STS_STOP)
    try:
        st.node.sdo[0x5801][1].raw = 0  # SSI_FRAME_LEN = 0: refused, ERR_PARA = 1
    except canopen.sdo.SdoAbortedError:
        pass
    assert st.node.sdo.upload(0x2000, 1)[7] & (ERR_PARA | STS_STOP) == ERR_PARA | STS_STOP
    st.node.sdo[0x5801][1].raw = PARA1_DEFAULT  # a valid set again
    assert not st.node.sdo.upload(0x2000, 1)[7] & ERR_PARA


def test_wire_message_deep_copy_is_a_plain_independent_message() -> None:
    msg = WireMessage(arbitration_id=0x18A, data=b"\x01\x02\x03", is_extended_id=False,
                      channel="wire", timestamp=1.5)
    clone = copy.deepcopy(msg)
    assert type(clone) is can.Message
    assert clone.equals(msg, timestamp_delta=None, check_channel=True)
    clone.data[0] = 0xFF
    assert msg.data[0] == 0x01, "the copy shares the payload"


def test_bridge_network_frames_equal_canopens(channel: str) -> None:
    frames = [(0x080, b"", False), (0x18B, bytes(range(8)), False), (0x1234567, b"\x05", False),
              (0x70B, b"", True)]
    tap = can.Bus(interface="virtual", channel=channel)
    ours, reference = BridgeNetwork(), canopen.Network()
    try:
        for network in (ours, reference):
            network.NOTIFIER_CYCLE = 0.05
            network.connect(interface="virtual", channel=channel)
            for can_id, data, remote in frames:
                network.send_message(can_id, data, remote)
        received = [tap.recv(1.0) for _ in range(2 * len(frames))]
    finally:
        ours.disconnect()
        reference.disconnect()
        tap.shutdown()
    assert all(m is not None for m in received), "a frame did not arrive"
    for mine, theirs in zip(received[:len(frames)], received[len(frames):]):
        assert type(mine) is can.Message
        assert mine.equals(theirs, timestamp_delta=None), f"{mine} != {theirs}"
