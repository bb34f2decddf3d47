"""CycleGate's hand-off: an armed cycle is run once, by the thread of the frame completing it.

Real slot tables on one gate, fed from a thread standing in for the receive thread. The
rules: exactly one of the frame's thread and the cycle thread runs an armed cycle; the frame
that completes it runs it at once; a cycle that never completes is the cycle
thread's at its timeout; a SYNC nobody armed (a register handshake's own) is run by nobody,
one during an armed cycle's wait leaves it armed;
the cycle thread's claim, and its wait, end only after the frame's thread has finished
publishing, and then at once.
"""

from __future__ import annotations

import struct
import threading
import time

from ssi_bridge.client.cycle_gate import CycleGate
from ssi_bridge.client.samples import SlotTable

IMAGE = bytes(range(8))


class Recorder:
    """on_complete: which threads ran it, optionally holding each run ``hold`` s."""

    def __init__(self, hold: float = 0.0) -> None:
        self.threads: list[str] = []
        self.hold = hold
        self.started = threading.Event()

    def __call__(self) -> None:
        self.started.set()
        self.threads.append(threading.current_thread().name)
        time.sleep(self.hold)


def _tables(gate: CycleGate, stations: int, slots: int) -> list[SlotTable]:
    return [SlotTable(slots, gate) for _ in range(stations)]


def _sync(gate: CycleGate, tables: list[SlotTable]) -> None:
    """What CanMaster.sync does before sending the SYNC."""
    with gate.cond:
        gate.open(len(tables))
        for t in tables:
            t.on_sync()


def _answer(table: SlotTable, slots: int, positions: bool = True) -> None:
    for s in range(1, slots + 1):
        table.on_image(s, IMAGE)
    if positions:
        for g in range((slots + 1) // 2):
            carried = [s for s in (2 * g + 1, 2 * g + 2) if s <= slots]
            table.on_positions(carried, struct.pack("<" + "i" * len(carried), *carried))


def _on_thread(name: str, job) -> None:
    t = threading.Thread(target=job, name=name)
    t.start()
    t.join(5)


def test_armed_cycle_runs_on_the_completing_frames_thread_once() -> None:
    gate = CycleGate()
    ran = Recorder()
    tables = _tables(gate, 2, 3)
    _sync(gate, tables)
    assert gate.arm(ran)
    _on_thread("rx", lambda: [_answer(t, 3) for t in tables])
    assert ran.threads == ["rx"], "the last frame's thread publishes, at once, once"
    assert gate.claim() is False, "the cycle thread must not publish it again"
    assert ran.threads == ["rx"]


def test_the_waiting_cycle_thread_wakes_once_the_publish_ended() -> None:
    """Not at the completing frame (it would compete for the CPU with the publish), not at
    its timeout (its next SYNC would be late): right after the receive thread's run."""
    gate = CycleGate()
    ran = Recorder(hold=0.2)
    tables = _tables(gate, 1, 2)
    woke: list[float] = []
    _sync(gate, tables)
    assert gate.arm(ran)

    def wait() -> None:
        assert gate.wait(3.0)
        woke.append(time.monotonic())

    waiter = threading.Thread(target=wait)
    waiter.start()
    time.sleep(0.05)
    start = time.monotonic()
    _on_thread("rx", lambda: _answer(tables[0], 2))
    ended = time.monotonic()
    waiter.join(3)
    assert ran.threads == ["rx"]
    assert woke and woke[0] - start >= 0.2, "woken before the publish ended"
    assert woke[0] - ended < 1.0, "left waiting for its timeout"


def test_incomplete_cycle_is_the_cycle_threads() -> None:
    gate = CycleGate()
    ran = Recorder()
    tables = _tables(gate, 1, 2)
    _sync(gate, tables)
    assert gate.arm(ran)
    _on_thread("rx", lambda: _answer(tables[0], 2, positions=False))
    assert not gate.wait(0.01)
    assert gate.claim() is True, "nobody completed it: the cycle thread decides it"
    assert ran.threads == []
    # its late positions arrive after the claim: nobody runs the cycle a second time
    _on_thread("rx", lambda: _answer(tables[0], 2))
    assert ran.threads == []


def test_cycle_complete_before_arming_is_the_cycle_threads() -> None:
    gate = CycleGate()
    ran = Recorder()
    tables = _tables(gate, 1, 1)
    _sync(gate, tables)
    _answer(tables[0], 1)
    assert gate.arm(ran) is False, "complete already: the caller publishes it itself"
    assert ran.threads == []


def test_unarmed_sync_is_run_by_nobody() -> None:
    """A register handshake's own SYNC (never armed) completes without a publish."""
    gate = CycleGate()
    ran = Recorder()
    tables = _tables(gate, 1, 2)
    _sync(gate, tables)
    _on_thread("rx", lambda: _answer(tables[0], 2))
    assert ran.threads == []
    assert gate.wait(0.0)


def test_a_handshakes_sync_during_the_wait_leaves_the_cycle_armed() -> None:
    """A register handshake's SYNC (another thread) while the cycle thread waits: the frame
    completing it completes the armed cycle, as the cycle thread's wait ended there before."""
    gate = CycleGate()
    ran = Recorder()
    tables = _tables(gate, 1, 1)
    _sync(gate, tables)
    assert gate.arm(ran)
    _sync(gate, tables)
    _on_thread("rx", lambda: _answer(tables[0], 1))
    assert ran.threads == ["rx"]
    assert gate.claim() is False


def test_a_cycle_claimed_at_its_timeout_is_run_by_nobody_else() -> None:
    gate = CycleGate()
    ran = Recorder()
    tables = _tables(gate, 1, 1)
    _sync(gate, tables)
    assert gate.arm(ran)
    assert gate.claim() is True
    _sync(gate, tables)  # the next SYNC, answered: nothing was armed for it
    _on_thread("rx", lambda: _answer(tables[0], 1))
    assert ran.threads == []


def test_a_failing_run_still_ends_the_wait() -> None:
    """An error in the receive thread's publish must not leave the cycle thread waiting."""
    gate = CycleGate()
    tables = _tables(gate, 1, 1)

    def boom() -> None:
        raise RuntimeError("publish failed")

    _sync(gate, tables)
    assert gate.arm(boom)
    errors: list[BaseException] = []

    def rx() -> None:
        try:
            _answer(tables[0], 1)
        except RuntimeError as err:
            errors.append(err)

    _on_thread("rx", rx)
    assert errors, "the error reaches the receive path (which logs and goes on)"
    assert gate.wait(0.5)
    assert gate.claim() is False


def test_claim_waits_for_the_receive_threads_run() -> None:
    gate = CycleGate()
    ran = Recorder(hold=0.2)
    tables = _tables(gate, 1, 1)
    _sync(gate, tables)
    assert gate.arm(ran)
    rx = threading.Thread(target=lambda: _answer(tables[0], 1), name="rx")
    rx.start()
    assert ran.started.wait(2)
    start = time.monotonic()
    assert gate.claim() is False
    assert time.monotonic() - start > 0.1, "claim returned while the cycle was being published"
    rx.join(2)
    assert ran.threads == ["rx"]
