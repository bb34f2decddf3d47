"""The cycle thread's schedule: absolute deadlines, skipped (not bursted) slots after overruns."""

from __future__ import annotations

import logging
import os
import threading
import time
from pathlib import Path

import pytest

from ssi_bridge.protocol import wire
from ssi_bridge.ros.cycle import CycleThread, cycle_waits
from ssi_bridge.base.realtime import fifo_this_thread, normal_this_thread


def test_runs_on_an_absolute_schedule_and_stops():
    stamps: list[float] = []
    loop = CycleThread(0.01, lambda: stamps.append(time.monotonic()))
    started = time.monotonic()
    loop.start()
    time.sleep(0.3)
    loop.stop()
    # the window is what the sleep really took (a loaded machine wakes this thread late):
    # at most one cycle per 10 ms of it, plus the one at the start and one being stopped.
    # A slot the thread woke too late for is skipped and counted (``missed``), never made up:
    # ran + missed covers the window, whatever the load
    window = time.monotonic() - started
    n = len(stamps)
    assert 2 <= n <= int(window * 100 + 1e-6) + 2, f"{n} cycles in {window:.3f} s at 100 Hz"
    assert n + loop.missed >= int(window * 100) - 2, (n, loop.missed, window)
    if loop.missed == 0:
        span = stamps[-1] - stamps[0]
        assert span / (n - 1) == pytest.approx(0.01, rel=0.15), "mean period drifts"
    time.sleep(0.05)
    assert len(stamps) == n, "no cycle may run after stop()"


def test_an_overrun_skips_missed_slots_instead_of_bursting():
    calls: list[float] = []
    slow = threading.Event()

    def step() -> None:
        calls.append(time.monotonic())
        if len(calls) == 3:
            slow.set()
            time.sleep(0.055)  # overruns 5 slots of 10 ms

    loop = CycleThread(0.01, step)
    loop.start()
    assert slow.wait(2.0)
    time.sleep(0.1)
    loop.stop()
    assert loop.missed >= 4, f"missed={loop.missed}"
    # the contract (CycleThread): a cycle less than half a period late runs at once, so
    # two calls may come close together once (a late wake-up on a busy machine), but after
    # that the next slot is at least half a period ahead: never three within 4 ms. Skipping
    # nothing would fire the 5 missed slots back to back.
    spans = [c - a for a, c in zip(calls[3:], calls[5:])]
    assert min(spans) > 0.004, f"a burst of cycles after the overrun: {spans}"
    assert len(calls) - 3 <= 0.1 / 0.01 + 2, f"{len(calls) - 3} cycles in 0.1 s of 10 ms"


def test_a_failing_step_does_not_end_the_loop():
    count = [0]

    def step() -> None:
        count[0] += 1
        raise RuntimeError("bad cycle")

    loop = CycleThread(0.005, step)
    loop.start()
    time.sleep(0.05)
    loop.stop()
    assert count[0] >= 3


def test_stop_ends_the_sleep_between_two_steps_at_once():
    """A stop during the sleep towards the next slot ends it at once, not at that slot."""
    steps: list[float] = []
    ended = threading.Event()
    loop = CycleThread(30.0, lambda: steps.append(time.monotonic()), end=ended.set)
    loop.start()
    deadline = time.monotonic() + 5.0
    while not steps and time.monotonic() < deadline:
        time.sleep(0.01)
    assert steps, "the first step never ran"
    time.sleep(0.05)  # the loop sleeps towards its next slot, 30 s away
    start = time.monotonic()
    loop.stop(5.0)
    assert ended.wait(1.0), "the loop slept on after stop()"
    assert time.monotonic() - start < 1.0
    assert len(steps) == 1


def test_period_must_be_positive():
    with pytest.raises(ValueError):
        CycleThread(0.0, lambda: None)


@pytest.mark.parametrize("slots, bitrate, rate_hz, fits", [
    (1, 500_000, 1000.0, True),    # 0.57 ms of wire per cycle
    (2, 500_000, 1000.0, True),    # 0.92 ms: fits the 1 ms period, keeps 1 kHz
    (8, 500_000, 1000.0, False),   # 3.35 ms
    (8, 1_000_000, 480.0, True),   # 1.68 ms of a 2.08 ms period
    (8, 125_000, 100.0, False),    # 13.4 ms of a 10 ms period
])
def test_a_cycle_waits_for_its_wire_time_only_when_it_does_not_fit_the_period(
        slots, bitrate, rate_hz, fits):
    """docs/canopen.md "Highest cycle rate": the worst-case SYNC + TPDOs of the slots."""
    period, on_wire = 1.0 / rate_hz, wire.cycle_seconds(slots, bitrate)
    assert (on_wire <= period) is fits
    first, starved = cycle_waits(period, on_wire)
    if fits:  # the next SYNC goes out at the period boundary, after the cycle's frames
        assert first == pytest.approx(0.9 * period)
    else:  # no SYNC while the cycle's TPDOs are on the wire: the wait outlasts them
        assert first >= on_wire > period
    assert starved >= first and starved <= max(first, 0.05)


# -- scheduling (docs/node.md "Scheduling") ----------------------------------------------------
def _may_use_fifo() -> bool:
    """Whether this process may put a thread on SCHED_FIFO (root, CAP_SYS_NICE, rtprio)."""
    seen: list[bool] = []
    probe = threading.Thread(target=lambda: seen.append(fifo_this_thread(1)))
    probe.start()
    probe.join()
    return seen[0]


def _thread_view() -> tuple[int, int, str]:
    """(policy, priority, kernel name) of the calling thread."""
    comm = Path(f"/proc/self/task/{threading.get_native_id()}/comm").read_text().strip()
    return os.sched_getscheduler(0), os.sched_getparam(0).sched_priority, comm


def _first_step_view(loop: CycleThread, seen: list) -> tuple[int, int, str]:
    loop.start()
    deadline = time.monotonic() + 5.0
    while not seen and time.monotonic() < deadline:
        time.sleep(0.01)
    loop.stop()
    assert seen, "the cycle never ran"
    return seen[0]


def test_the_cycle_runs_at_its_fifo_priority_under_its_kernel_name(caplog):
    """cycle_priority: the step runs SCHED_FIFO at the priority and ``top -H`` shows the
    thread as ssi_cycle; without the right to it, normal scheduling and one INFO line."""
    seen: list = []
    loop = CycleThread(0.01, lambda: seen.append(_thread_view()), priority=3)
    with caplog.at_level(logging.INFO, logger="ssi_bridge.ros.cycle"):
        policy, priority, comm = _first_step_view(loop, seen)
    assert comm == "ssi_cycle"
    if _may_use_fifo():
        assert (policy, priority) == (os.SCHED_FIFO, 3)
        assert loop.scheduling == "SCHED_FIFO 3"
        assert "not permitted" not in caplog.text
    else:
        assert (policy, priority) == (os.SCHED_OTHER, 0)
        assert loop.scheduling == "normal"
        assert "ssi_cycle thread runs with normal scheduling: SCHED_FIFO 3 not permitted" \
            in caplog.text


def test_priority_zero_is_normal_scheduling(caplog):
    seen: list = []
    loop = CycleThread(0.01, lambda: seen.append(_thread_view()), priority=0)
    with caplog.at_level(logging.INFO, logger="ssi_bridge.ros.cycle"):
        policy, priority, _ = _first_step_view(loop, seen)
    assert (policy, priority) == (os.SCHED_OTHER, 0)
    assert loop.scheduling == "normal" and "not permitted" not in caplog.text


def test_a_priority_the_kernel_refuses_runs_the_cycle_normally(caplog):
    """SCHED_FIFO priorities are 1..99 on Linux: 100 is refused even for root."""
    seen: list = []
    loop = CycleThread(0.01, lambda: seen.append(_thread_view()), priority=100)
    with caplog.at_level(logging.INFO, logger="ssi_bridge.ros.cycle"):
        policy, _, _ = _first_step_view(loop, seen)
    assert policy == os.SCHED_OTHER and loop.scheduling == "normal"
    assert "SCHED_FIFO 100 not permitted" in caplog.text


def test_a_thread_the_cycle_starts_for_slow_work_goes_back_to_normal_scheduling():
    """A thread inherits its creator's policy; the salvage of a failed recording runs
    normally (normal_this_thread) even when the cycle that started it is SCHED_FIFO."""
    if not _may_use_fifo():
        pytest.skip("this process may not use SCHED_FIFO: nothing is inherited")
    views: dict[str, int] = {}

    def worker() -> None:
        views["inherited"] = os.sched_getscheduler(0)
        normal_this_thread()
        views["after"] = os.sched_getscheduler(0)

    def step() -> None:
        if not views:
            t = threading.Thread(target=worker)
            t.start()
            t.join()

    loop = CycleThread(0.01, step, priority=2)
    loop.start()
    deadline = time.monotonic() + 5.0
    while "after" not in views and time.monotonic() < deadline:
        time.sleep(0.01)
    loop.stop()
    assert views == {"inherited": os.SCHED_FIFO, "after": os.SCHED_OTHER}


def test_the_garbage_collector_runs_on_the_cycle_thread_with_time_to_spare():
    """While a cycle thread runs, no other thread triggers a collection (the receive thread
    allocates per frame); the cycle thread collects between steps, by CPython's thresholds;
    automatic collection is back when it stops (base/gc_pacing.py)."""
    import gc

    was = gc.isenabled()
    gc.enable()
    collected_on: list[str] = []

    def note(phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            collected_on.append(threading.current_thread().name)

    def allocate_cycles() -> None:  # a step that leaves reference cycles behind
        for _ in range(200):
            a: list[object] = []
            a.append(a)

    loop = CycleThread(0.01, allocate_cycles, name="ssi_cycle_gc_test")
    gc.callbacks.append(note)
    try:
        loop.start()
        time.sleep(0.1)
        assert not gc.isenabled()
        for _ in range(5 * gc.get_threshold()[0]):  # this thread allocates: no collection here
            a: list[object] = []
            a.append(a)
        time.sleep(0.3)
        loop.stop()
    finally:
        gc.callbacks.remove(note)
        enabled_after = gc.isenabled()
        if not was:
            gc.disable()
    assert enabled_after
    assert collected_on and set(collected_on) == {"ssi_cycle_gc_test"}, collected_on
    # each of the pacing's collections was seen (the thread, ending, may also have collected
    # once after the collector came back on)
    assert 1 <= sum(loop.pacing.collections) <= len(collected_on)


def test_status_readers_are_counted_again_by_time_not_by_cycles() -> None:
    """``~/status`` is built only for a reader, whose count is read again
    ``STATUS_READERS_EVERY_S`` after the last count (ros/cycle_publish.py, docs/node.md): by
    time, so a listen-only node whose cycles are another master's slow SYNCs (10 Hz against a
    publish_rate of 2000) sees a new reader as promptly as a master does."""
    from types import SimpleNamespace

    from ssi_bridge.ros.cycle_publish import STATUS_READERS_EVERY_S, CyclePublisher

    node = SimpleNamespace(context=SimpleNamespace(on_shutdown=lambda cb: None),
                           settings=SimpleNamespace(publish_rate=2000.0))
    readers = [0]
    pub = SimpleNamespace(get_subscription_count=lambda: readers[0])
    cycles = CyclePublisher(node)
    assert cycles._status_read(pub) is False  # a first cycle: counted, nobody reads
    readers[0] = 1  # a reader comes
    time.sleep(STATUS_READERS_EVERY_S + 0.01)  # one slow SYNC later
    assert cycles._status_read(pub) is True
    readers[0] = 0
    assert cycles._status_read(pub) is True  # within the interval: the count kept
    other = SimpleNamespace(get_subscription_count=lambda: readers[0])
    assert cycles._status_read(other) is False  # a publisher made anew: counted at once
