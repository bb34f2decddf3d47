"""The cycle thread's schedule: absolute deadlines, skipped (not bursted) slots after overruns."""

from __future__ import annotations

import threading
import time

import pytest

from ssi_bridge.ros.cycle import CycleThread


def test_runs_on_an_absolute_schedule_and_stops():
    stamps: list[float] = []
    loop = CycleThread(0.01, lambda: stamps.append(time.monotonic()))
    loop.start()
    time.sleep(0.3)
    loop.stop()
    n = len(stamps)
    assert 20 <= n <= 32, f"{n} cycles in 0.3 s at 100 Hz"
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
    gaps = [b - a for a, b in zip(calls[3:], calls[4:])]
    assert min(gaps) > 0.002, "after an overrun the loop must not fire a burst of cycles"


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


def test_period_must_be_positive():
    with pytest.raises(ValueError):
        CycleThread(0.0, lambda: None)
