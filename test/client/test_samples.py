"""SlotTable: cycle completion, one wake-up per cycle, handshake waiters woken per image."""

from __future__ import annotations

import struct
import threading
import time

import pytest

from ssi_bridge.client.samples import SlotTable
from ssi_bridge.core.cycle_log import StationLog

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


def _loss(log: StationLog, seq: int) -> tuple[float, float] | None:
    """(wire time, share of slot 1's two TPDOs missing) of SYNC ``seq`` as the cycle's frame
    log sees it, fed by the table; None for a SYNC it does not know."""
    at = log.sync_time(seq)
    return None if at is None else (at, log.verdict(1, seq).missing)


def _logged_table() -> tuple[SlotTable, StationLog]:
    table = SlotTable(1)
    log = StationLog(latch_bound=0.001)
    table.sink = log
    return table, log


def test_loss_counts_an_answer_handled_after_the_next_sync_for_its_own_sync() -> None:
    # CiA 301: synchronous TPDOs follow their SYNC on the wire; a master that handles them
    # late (after it sent the next SYNC) still sees by their wire time which SYNC they
    # answered, so a starved process is no lost frame (the stale ratio measures the bus)
    table, log = _logged_table()
    t1 = table.on_sync(100.000)
    t2 = table.on_sync(100.001)  # the next SYNC went out before SYNC 1's answers were handled
    table.on_image(1, IMAGE, timestamp=t1 + 0.0002)
    table.on_positions([1], struct.pack("<ii", 7, 0), timestamp=t1 + 0.0003)
    assert _loss(log, 1) == (t1, 0.0)
    assert _loss(log, 2) == (t2, 1.0)  # nothing answered SYNC 2 yet
    table.on_image(1, IMAGE, timestamp=t2 + 0.0002)
    assert _loss(log, 2) == (t2, 0.5)  # its position frame was lost
    assert _loss(log, 3) is None  # no such SYNC yet


def test_loss_follows_a_frame_the_sync_time_moves_to_the_cycle_before() -> None:
    # a TPDO handled before the SYNC's own wire time was known, that ended on the wire
    # before it, answered the SYNC before (SlotTable.set_sync_time)
    table, log = _logged_table()
    t1 = table.on_sync(200.000)
    table.on_sync(200.0008)  # sent; the wire has not yet said when it ended
    table.on_image(1, IMAGE, timestamp=200.0009)  # after the SYNC's send: counted for it ...
    assert _loss(log, 2) == (200.0008, 0.5)
    t2 = table.set_sync_time(200.001)  # ... but it ended on the wire before that SYNC
    assert _loss(log, 1) == (t1, 0.5)
    assert _loss(log, 2) == (t2, 1.0)
