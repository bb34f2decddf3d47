"""The station's per-cycle send path: the same frames and bytes, fewer Python steps.

``WireMessage.frame`` and its deep copy against python-can's own constructor field by field,
``BridgeNetwork.send_messages`` (one SYNC's TPDOs as one batch) against ``send_message``,
``LossyBus`` reading its inner bus one receive step at a time with the inner filters kept,
and the slot-pair packer of the encoder default PDOs against the per-entry readers.
"""

from __future__ import annotations

import copy

import can
import pytest

from ssi_bridge.sim.gateway.bus import BridgeNetwork, LossyBus, WireMessage
from ssi_bridge.sim.gateway.objects import EncoderObjects
from ssi_bridge.protocol.registers import Reg
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

from support.virtual_bus import ScriptedReader

FIELDS = [name for name in can.Message.__slots__ if name != "__weakref__"]


def _fields(msg: can.Message) -> dict[str, object]:
    return {name: getattr(msg, name) for name in FIELDS}


@pytest.mark.parametrize("can_id, data, remote", [
    (0x080, b"", False), (0x18B, bytes(range(8)), False), (0x1234567, b"\x05", False),
    (0x70B, b"", True), (0x000, [0x01, 0x0B], False), (0x080, None, False),
    (0x60B, bytearray(b"\x40\x00\x10\x00"), False), (0x70B, b"\x01", True),
])
def test_wire_frame_equals_the_message_canopen_builds(can_id: int, data, remote: bool) -> None:
    expected = can.Message(arbitration_id=can_id, is_extended_id=can_id > 0x7FF, data=data,
                           is_remote_frame=remote)
    frame = WireMessage.frame(can_id, data, remote)
    assert isinstance(frame, WireMessage)
    assert _fields(frame) == _fields(expected)
    assert type(frame.data) is bytearray and frame.data is not data


def test_wire_message_deep_copy_sets_every_field() -> None:
    msg = WireMessage.frame(0x18A, b"\x01\x02", False)
    msg.timestamp, msg.channel, msg.is_rx, msg.dlc = 2.5, "wire", False, 2
    clone = copy.deepcopy(msg)
    assert type(clone) is can.Message
    assert _fields(clone) == _fields(msg), "a field of can.Message was not copied"
    assert clone.data is not msg.data


class _RefusingBus(can.BusABC):
    """Records what it is sent; refuses the COB-IDs in ``refuse``."""

    def __init__(self, refuse: set[int]) -> None:
        self.refuse = refuse
        self.sent: list[can.Message] = []
        super().__init__(channel="refusing")

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if msg.arbitration_id in self.refuse:
            raise can.CanOperationError(f"0x{msg.arbitration_id:03X} refused")
        self.sent.append(msg)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        return None, False


def test_send_messages_sends_what_send_message_sends_and_reports_refusals() -> None:
    frames = [(0x18B, bytes(range(8))), (0x28B, b"\x01\x02\x03\x04"), (0x1CB, b"")]
    batch, single = _RefusingBus({0x28B}), _RefusingBus({0x28B})
    failed = BridgeNetwork(batch).send_messages(frames)
    for can_id, data in frames:
        try:
            BridgeNetwork(single).send_message(can_id, data)
        except can.CanError:
            pass
    assert [(can_id, type(err)) for can_id, err in failed] == [
        (0x28B, can.CanOperationError)], "the refused frame is not reported"
    assert [_fields(m) for m in batch.sent] == [_fields(m) for m in single.sent]
    assert [m.arbitration_id for m in batch.sent] == [0x18B, 0x1CB], "refusal stopped the rest"


def test_send_messages_needs_a_bus() -> None:
    with pytest.raises(RuntimeError):
        BridgeNetwork().send_messages([(0x18B, b"")])


def test_lossy_bus_keeps_the_inner_filters(channel: str) -> None:
    inner = can.Bus(interface="virtual", channel=channel)
    inner.set_filters([{"can_id": 0x181, "can_mask": 0x7FF}])
    lossy = LossyBus(inner)
    tx = can.Bus(interface="virtual", channel=channel)
    try:
        for can_id in (0x182, 0x181, 0x183):
            tx.send(can.Message(arbitration_id=can_id, is_extended_id=False, data=b"\x07"))
        got = lossy.recv(1.0)
        assert got is not None and got.arbitration_id == 0x181
        assert lossy.recv(0.05) is None, "a filtered frame came through"
    finally:
        tx.shutdown()
        lossy.shutdown()


def test_lossy_bus_keeps_its_own_filters(channel: str) -> None:
    lossy = LossyBus(can.Bus(interface="virtual", channel=channel))
    tx = can.Bus(interface="virtual", channel=channel)
    try:
        tx.send(can.Message(arbitration_id=0x185, is_extended_id=False, data=b"\x01"))
        assert lossy.recv(1.0).arbitration_id == 0x185  # type: ignore[union-attr]
        lossy.set_filters([{"can_id": 0x181, "can_mask": 0x7FF}])
        for can_id in (0x182, 0x181):
            tx.send(can.Message(arbitration_id=can_id, is_extended_id=False, data=b"\x07"))
        assert lossy.recv(1.0).arbitration_id == 0x181  # type: ignore[union-attr]
        assert lossy.recv(0.02) is None
    finally:
        tx.shutdown()
        lossy.shutdown()


def test_lossy_bus_drops_received_frames_on_the_step_path(channel: str) -> None:
    lossy = LossyBus(can.Bus(interface="virtual", channel=channel), 1.0, drop_received=True)
    tx = can.Bus(interface="virtual", channel=channel)
    try:
        tx.send(can.Message(arbitration_id=0x181, is_extended_id=False, data=b"\x07"))
        assert lossy.recv(0.05) is None and lossy.dropped == 1
    finally:
        tx.shutdown()
        lossy.shutdown()


@pytest.mark.parametrize("entries", [
    [(0x6820, 1), (0x6820, 2)], [(0x6820, 2), (0x6820, 1)], [(0x6820, 1), (0x6820, 2), (0x6820, 3)],
])
def test_position_packer_equals_the_entry_readers(entries: list[tuple[int, int]]) -> None:
    modules = [Xn1Ssi(ScriptedReader(v), slot=s + 1) for s, v in enumerate((7, 5000, 0xFFFFFF))]
    objects = EncoderObjects(modules)
    modules[0].write_register(Reg.REG_OFFSET, 10)  # 7 - 10: negative Integer32
    for module in modules:
        module.cycle(0.0)
    packer = objects.pdo_packer(entries)
    assert packer is not None
    joined = b"".join(objects.pdo_reader(i, s)() for i, s in entries)  # type: ignore[misc]
    assert packer() == joined
    assert int.from_bytes(joined[:4], "little", signed=True) in (-3, 5000)


@pytest.mark.parametrize("entries", [
    [(0x6820, 1)], [(0x6820, 1), (0x2000, 2)], [(0x6820, 1), (0x6820, 9)], [],
])
def test_position_packer_only_for_position_pairs(entries: list[tuple[int, int]]) -> None:
    objects = EncoderObjects([Xn1Ssi(ScriptedReader(1), slot=s) for s in (1, 2)])
    assert objects.pdo_packer(entries) is None
