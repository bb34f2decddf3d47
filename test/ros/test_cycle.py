"""The cycle thread's schedule: absolute deadlines, skipped (not bursted) slots after overruns."""

from __future__ import annotations

import threading
import time

import pytest

from ssi_bridge.gateway import wire
from ssi_bridge.ros.cycle import CycleThread, cycle_waits


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
