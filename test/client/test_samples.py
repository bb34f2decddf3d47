"""SlotTable: cycle completion, one wake-up per cycle, handshake waiters woken per image."""

from __future__ import annotations

import struct
import threading
import time

import pytest

from ssi_bridge.client.samples import SlotTable

IMAGE = bytes(range(8))


class CountingCondition(threading.Condition):
    """A Condition that counts ``notify_all`` calls."""

    def __init__(self) -> None:
        super().__init__()
        self.wakeups = 0

    def notify_all(self) -> None:
        self.wakeups += 1
        super().notify_all()


def _feed(table: SlotTable, slots: int) -> None:
    for s in range(1, slots + 1):
        table.on_image(s, IMAGE)
    for g in range((slots + 1) // 2):
        carried = [s for s in (2 * g + 1, 2 * g + 2) if s <= slots]
        table.on_positions(carried, struct.pack("<" + "i" * len(carried), *carried))


@pytest.mark.parametrize("slots", [1, 3, 8])
def test_cycle_completes_once_everything_arrived(slots: int) -> None:
    table = SlotTable(slots)
    assert not table.cycle_complete()
    table.on_sync()
    for s in range(1, slots + 1):
        table.on_image(s, IMAGE)
        table.on_image(s, IMAGE)  # a duplicate does not count twice
    assert not table.cycle_complete(), "complete without positions"
    _feed(table, slots)
    assert table.cycle_complete()
    assert table.wait_cycle(0.0)
    assert [table.latest(s).position for s in range(1, slots + 1)] == list(range(1, slots + 1))
    assert table.latest(1).counter == 3
    table.on_sync()
    assert not table.cycle_complete(), "a new SYNC must reopen the cycle"
    assert not table.wait_cycle(0.01)


def test_one_wakeup_per_cycle() -> None:
    table = SlotTable(8)
    table.cond = CountingCondition()
    for _ in range(5):
        table.on_sync()
        _feed(table, 8)
        assert table.wait_cycle(0.0)
    assert table.cond.wakeups == 5


def test_wait_cycle_returns_when_the_last_frame_arrives() -> None:
    table = SlotTable(2)
    table.on_sync()
    done = threading.Event()
    result: list[bool] = []

    def waiter() -> None:
        result.append(table.wait_cycle(5.0))
        done.set()

    thread = threading.Thread(target=waiter)
    thread.start()
    _feed(table, 2)
    assert done.wait(5.0), "wait_cycle was not woken by the last frame"
    thread.join()
    assert result == [True]


def test_handshake_waiter_woken_by_a_single_image() -> None:
    table = SlotTable(4)
    table.on_sync()
    table.slot(2).edit_seq = 0
    got: list[object] = []
    thread = threading.Thread(target=lambda: got.append(table.next_input(2, 5.0)))
    thread.start()
    deadline = time.monotonic() + 5.0
    while not table._input_waiters:  # wait until it sleeps, so the image must wake it
        assert time.monotonic() < deadline, "next_input never started waiting"
        time.sleep(0.001)
    table.on_image(2, IMAGE)  # the cycle is far from complete
    thread.join(5.0)
    assert not thread.is_alive(), "next_input not woken by its image"
    assert got and got[0] is not None and got[0].reg_rd_adr == IMAGE[4] & 0x3F
