"""The garbage collector paced by the cycle thread (base/gc_pacing.py): off while a pacing
runs, CPython's generations collected by its own counters when there is time, back on after."""

from __future__ import annotations

import gc
import threading

import pytest

from ssi_bridge.base.gc_pacing import FORCE_FACTOR, CollectorPacing


@pytest.fixture
def pacing():
    was = gc.isenabled()
    gc.enable()
    p = CollectorPacing()
    p.start()
    try:
        yield p
    finally:
        p.stop()
        if not was:
            gc.disable()


def _young_garbage(n: int) -> None:
    """``n`` tracked objects that stay in the young generation until collected (cycles).
    CPython's young count is allocations minus frees, so callers leave a margin over a
    threshold for what the test machinery frees meanwhile."""
    for _ in range(n):
        a: list[object] = []
        a.append(a)


def test_no_automatic_collection_while_a_pacing_runs(pacing):
    limit0 = gc.get_threshold()[0]
    before = gc.get_stats()[0]["collections"]
    _young_garbage(3 * limit0)
    assert gc.get_stats()[0]["collections"] == before  # the allocating thread never collected
    assert gc.get_count()[0] >= limit0


def test_step_collects_the_young_generation_when_due_and_spare(pacing):
    limit0 = gc.get_threshold()[0]
    gc.collect()
    assert pacing.step(spare=True) == -1  # nothing due
    _young_garbage(limit0 + 200)
    assert pacing.step(spare=False) == -1  # due, but no time to spare and no backlog
    assert pacing.step(spare=True) == 0
    assert gc.get_count()[0] < limit0
    assert pacing.collections[0] == 1


def test_a_backlog_is_collected_even_without_spare_time(pacing):
    limit0 = gc.get_threshold()[0]
    _young_garbage(FORCE_FACTOR * limit0 + limit0)  # margin: frees count down
    assert pacing.step(spare=False) == 0


def test_older_generations_follow_cpythons_thresholds(pacing):
    limit0, limit1, _ = gc.get_threshold()
    gc.collect()
    for _ in range(limit1):
        _young_garbage(limit0 + 200)
        assert pacing.step(spare=True) == 0
    _young_garbage(limit0 + 200)
    assert pacing.step(spare=True) == 1  # the middle generation's count reached its threshold


def test_cyclic_garbage_is_freed_by_the_steps():
    import weakref

    class Node:
        pass

    p = CollectorPacing()
    p.start()
    try:
        a, b = Node(), Node()
        a.other, b.other = b, a  # type: ignore[attr-defined]
        ref = weakref.ref(a)
        del a, b
        _young_garbage(gc.get_threshold()[0] + 200)
        assert ref() is not None  # nothing collected it yet
        assert p.step(spare=True) == 0
        assert ref() is None
    finally:
        p.stop()


def test_collection_comes_back_when_the_last_pacing_stops():
    was = gc.isenabled()
    gc.enable()
    one, two = CollectorPacing(), CollectorPacing()
    try:
        one.start()
        two.start()
        assert not gc.isenabled() and gc.get_freeze_count() > 0
        one.stop()
        assert not gc.isenabled()  # the other still runs
        two.stop()
        assert gc.isenabled() and gc.get_freeze_count() == 0
        two.stop()  # a stop too many changes nothing
        assert gc.isenabled()
    finally:
        if not was:
            gc.disable()


def test_pacings_on_several_threads_leave_the_collector_on():
    was = gc.isenabled()
    gc.enable()
    try:
        def run() -> None:
            p = CollectorPacing()
            p.start()
            _young_garbage(100)
            p.step(spare=True)
            p.stop()

        threads = [threading.Thread(target=run) for _ in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert gc.isenabled()
    finally:
        if not was:
            gc.disable()
