"""The gateway's CAN controller receive FIFO (sim/gateway/controller.py), step by step.

What a CAN controller does with frames its device does not take out in time: it holds a few
(RX_FIFO_DEPTH, a bxCAN receive FIFO's three mailboxes) and loses the rest, an overrun that
CiA 301 reports as EMCY 0x8110 "CAN overrun (objects lost)". Frames come with the times the
model is given (wire time, arrival in this process, the moment the thread takes them): no
clock, no bus.
"""

from __future__ import annotations

import math

import pytest

from ssi_bridge.sim.gateway.controller import HANDLING_GRACE_S, RX_FIFO_DEPTH, RxFifo

PERIOD = 0.001  # a frame every ms (a 1 kHz SYNC)


def test_frames_taken_within_the_grace_are_handled_at_their_wire_time_and_never_lost() -> None:
    fifo = RxFifo()
    for k in range(1000):
        w = 10.0 + k * PERIOD
        # the thread takes each frame up to the grace after it arrived: scheduling, no stall
        assert fifo.admit(w, w, w + HANDLING_GRACE_S * (k % 3) / 2) == w
    assert (fifo.lost, fifo.overruns, fifo.late) == (0, 0, 0)


def test_a_senders_delay_is_not_the_stations() -> None:
    # the datagram left its (late) sender 30 ms after the frame's end on the wire; the station
    # took it at once: handled at the wire time, as a device that heard it on the wire
    fifo = RxFifo()
    assert fifo.admit(5.0, 5.030, 5.0301) == 5.0
    assert fifo.late == 0


def test_a_stalled_station_keeps_the_fifo_and_loses_the_rest_in_one_episode() -> None:
    fifo = RxFifo()
    stall_end = 12.0  # stalled from 10.0: frames of 10.0-12.0 wait, then are taken at once
    handled, lost = [], []
    for k in range(3000):
        w = 10.0 + k * PERIOD
        now = max(stall_end, w) + k * 1e-6
        t = fifo.admit(w, w, now)
        (lost if t is None else handled).append((w, t))
    kept_in_stall = [(w, t) for w, t in handled if w < stall_end]
    assert len(kept_in_stall) == RX_FIFO_DEPTH  # what the FIFO held
    # each latched when taken, not at its wire time (the device handled it late)
    for w, t in kept_in_stall:
        assert t == pytest.approx(stall_end, abs=1e-3)
    # lost: every frame of the stall beyond the FIFO, until frames came after the stall
    assert fifo.lost == len(lost)
    assert all(w < stall_end + PERIOD for w, _ in lost)
    assert len(lost) >= 2000 - RX_FIFO_DEPTH - 2
    assert fifo.overruns == 1  # one episode: one EMCY 0x8110
    assert fifo.episode_lost == 0  # over: frames after the stall are taken again
    times = [t for _, t in handled]
    assert times == sorted(times)  # handling never goes backwards


def test_each_stall_is_its_own_overrun_episode() -> None:
    fifo = RxFifo(depth=2)
    now = 0.0
    for stall in (1.0, 3.0):
        for k in range(100):  # 100 ms stalled
            w = stall + k * PERIOD
            fifo.admit(w, w, stall + 0.1)
        for k in range(100, 200):  # then on time
            w = stall + k * PERIOD
            now = w
            assert fifo.admit(w, w, now) is not None
    assert fifo.overruns == 2
    assert fifo.lost == 2 * (100 - 2)


def test_queueing_keeps_every_frame_handled_at_its_wire_time() -> None:
    fifo = RxFifo()
    fifo.set_queueing(True)
    for k in range(2000):
        w = 10.0 + k * PERIOD
        assert fifo.admit(w, w, 12.0) == w  # latched where the SYNC was, answered late
    assert fifo.lost == 0
    fifo.set_queueing(False)
    assert fifo.admit(13.0, 13.0, 13.0) == 13.0


def test_an_unbounded_grace_never_overruns() -> None:
    fifo = RxFifo(grace=math.inf)  # a station in its master's own process
    for k in range(500):
        w = 1.0 + k * PERIOD
        assert fifo.admit(w, w, 5.0) == w
    assert fifo.lost == 0


@pytest.mark.parametrize("depth, grace", [(0, 0.02), (3, -1.0), (3, math.nan)])
def test_impossible_settings_are_refused(depth: int, grace: float) -> None:
    with pytest.raises(ValueError):
        RxFifo(depth, grace)
