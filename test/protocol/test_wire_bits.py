"""A frame's bits on the wire (``protocol/wire.frame_bits``, one pass a byte) are the bit-by-bit
count of ISO 11898-1 (``reference_frame_bits``: SOF..CRC stuffed, then 13 tail bits)."""

from __future__ import annotations

import random

import pytest

from ssi_bridge.protocol.wire import TAIL_BITS, frame_bits, reference_frame_bits, worst_frame_bits


def test_random_frames_count_as_the_bit_walk() -> None:
    rng = random.Random(11)
    for _ in range(20000):
        can_id = rng.randrange(0x800)
        # runs of equal bits are where stuffing happens: all-zero and all-one bytes often
        data = bytes(rng.choice([0x00, 0xFF, rng.randrange(256)]) for _ in range(rng.randrange(9)))
        bits = frame_bits(can_id, data)
        assert bits == reference_frame_bits(can_id, data), (hex(can_id), data.hex())
        assert bits == frame_bits(can_id, bytearray(data))
        assert 34 + 8 * len(data) + TAIL_BITS <= bits <= worst_frame_bits(len(data))


def test_a_remote_frame_has_no_data_field() -> None:
    for can_id in (0x000, 0x701, 0x7FF):
        assert frame_bits(can_id, b"", remote=True) == reference_frame_bits(can_id, b"", True)
        # the payload of a remote frame is no data field
        assert frame_bits(can_id, b"\x01\x02", remote=True, dlc=0) == frame_bits(can_id, b"", True)


@pytest.mark.parametrize("can_id", [-1, 0x800])
def test_an_identifier_beyond_11_bits_is_refused(can_id: int) -> None:
    with pytest.raises(ValueError, match="11-bit"):
        frame_bits(can_id, b"")
