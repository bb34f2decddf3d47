"""Which SYNC a TPDO answers: the frame log's rules on frame sequences, without a bus.

Each test feeds a :class:`StationLog` the events a master sees on the wire (its own SYNCs with
their sequence numbers, another producer's SYNCs, each slot's process input image and position
with their wire times) and checks the verdict against the rules of ``core/cycle_log.py``:
a station answers each SYNC it handles with one image and one position per slot (000 Table 15,
synchronous TPDOs, transmission type 1), after the SYNC (CiA 301 synchronous window).
"""

from __future__ import annotations

import pytest

from ssi_bridge.core.cycle_log import (LATE, NO_ANSWER, PARTIAL, SURPLUS, UNKNOWN_SYNC,
                                       UNSETTLED, StationLog)

P = 0.005        # 200 Hz cycles
BOUND = 0.001    # the log's latch bound (s)
IMG = bytes(8)


def _answer(log: StationLog, t: float, value: int, slot: int = 1, gap: float = 0.0002) -> None:
    """A station's answer for ``slot``: the image, then the position ``gap`` later."""
    log.image(slot, t, IMG, 0)
    log.position(slot, t + gap, value)


def _steady(log: StationLog, cycles: int, delay: float = 0.0003) -> None:
    """``cycles`` own SYNCs from seq 1, each answered ``delay`` after it (value = seq)."""
    for k in range(1, cycles + 1):
        log.sync(k, k * P)
        _answer(log, k * P + delay, k)


def test_an_answer_in_step_and_in_time_is_vouched_for_at_its_sync():
    log = StationLog(BOUND)
    _steady(log, 3)
    v = log.verdict(1, 3)
    assert v.reason == "" and v.sample is not None
    assert v.sample.position == 3 and v.sample.sync_time == 3 * P
    assert v.sample.delay == pytest.approx(0.0003)


def test_the_first_two_syncs_lack_the_windows_before_them_so_are_not_vouched_for():
    log = StationLog(BOUND)
    _steady(log, 2)
    assert log.verdict(1, 1).reason == UNSETTLED
    assert log.verdict(1, 2).reason == UNSETTLED


def test_an_answer_later_than_the_bound_is_set_aside():
    """The latch lies somewhere between the SYNC and the answer: too wide to vouch for."""
    log = StationLog(BOUND)
    _steady(log, 2)
    log.sync(3, 3 * P)
    _answer(log, 3 * P + 0.0025, 3)
    assert log.verdict(1, 3).reason == LATE


def test_a_sync_without_an_answer_and_a_partial_one():
    log = StationLog(BOUND)
    _steady(log, 2)
    log.sync(3, 3 * P)
    assert log.verdict(1, 3).reason == NO_ANSWER
    log.image(1, 3 * P + 0.0003, IMG, 0)  # the position TPDO lost on the wire
    v = log.verdict(1, 3)
    assert v.reason == PARTIAL and v.missing == 0.5


def test_after_a_stall_the_backlog_is_set_aside_until_the_station_is_in_step_again():
    """A station that queued SYNCs answers them in a burst after the stall, each latched at
    its own (old) SYNC: the first answer after the current SYNC is not its answer."""
    log = StationLog(BOUND)
    _steady(log, 3)
    for k in range(4, 10):              # stalled: SYNCs 4-9 get no answer in their windows
        log.sync(k, k * P)
    log.sync(10, 10 * P)
    for j, k in enumerate(range(4, 11)):  # the burst: answers to 4..10 right after SYNC 10
        _answer(log, 10 * P + 0.0001 + j * 0.0004, k, gap=0.0001)
    assert log.verdict(1, 10).reason == SURPLUS
    log.sync(11, 11 * P)
    _answer(log, 11 * P + 0.0003, 11)
    assert log.verdict(1, 11).reason == UNSETTLED   # the window before was the burst
    for k in (12, 13):
        log.sync(k, k * P)
        _answer(log, k * P + 0.0003, k)
    assert log.verdict(1, 12).reason == UNSETTLED   # two windows in step are needed
    v = log.verdict(1, 13)
    assert v.sample is not None and v.sample.position == 13


def test_one_leftover_of_a_backlog_in_the_window_is_not_taken_for_the_sync():
    """The burst ends with exactly one old answer after SYNC k, k's own answer lost: one
    answer in the window, in time, but the station was not in step when k came."""
    log = StationLog(BOUND)
    _steady(log, 3)
    log.sync(4, 4 * P)                   # stalled through 4
    log.sync(5, 5 * P)
    _answer(log, 5 * P + 0.0002, 4)      # 4's answer, latched at 4, sent after 5
    assert log.verdict(1, 5).reason == UNSETTLED


def test_a_duplicated_frame_is_a_surplus():
    log = StationLog(BOUND)
    _steady(log, 2)
    log.sync(3, 3 * P)
    _answer(log, 3 * P + 0.0003, 3)
    log.position(1, 3 * P + 0.0006, 3)
    assert log.verdict(1, 3).reason == SURPLUS


def test_reordered_frames_of_one_answer_still_count():
    """The position may reach the master before the image (another COB-ID's priority)."""
    log = StationLog(BOUND)
    _steady(log, 2)
    log.sync(3, 3 * P)
    log.position(1, 3 * P + 0.0002, 3)
    log.image(1, 3 * P + 0.0004, IMG, 0)
    assert log.verdict(1, 3).sample is not None


def test_a_foreign_sync_in_the_windows_before_ours_is_not_in_step_even_if_answered():
    """Between another producer's SYNCs a saturated station can stay one answer behind with
    every answer looking prompt: only the master's own windows show it in step (rule 3)."""
    log = StationLog(BOUND)
    _steady(log, 2)
    log.foreign_sync(3 * P - 0.002)
    _answer(log, 3 * P - 0.0017, 99)     # its answer to the foreign SYNC, in that window
    log.sync(3, 3 * P)
    _answer(log, 3 * P + 0.0003, 3)
    assert log.verdict(1, 3).reason == UNSETTLED
    for k in (4, 5):
        log.sync(k, k * P)
        _answer(log, k * P + 0.0003, k)
    assert log.verdict(1, 4).reason == UNSETTLED   # the foreign window is one of the two
    v = log.verdict(1, 5)
    assert v.sample is not None and v.sample.position == 5


def test_an_answer_to_a_foreign_sync_that_comes_after_ours_is_not_ours():
    """A foreign SYNC just before ours, answered only after ours: the station was not in step
    (its answer to the foreign SYNC is the first after ours)."""
    log = StationLog(BOUND)
    _steady(log, 2)
    log.foreign_sync(3 * P - 0.0001)
    log.sync(3, 3 * P)
    _answer(log, 3 * P + 0.0002, 99)     # latched at the foreign SYNC
    assert log.verdict(1, 3).reason == UNSETTLED


def test_a_foreign_sync_after_ours_ends_our_window():
    log = StationLog(BOUND)
    _steady(log, 2)
    log.sync(3, 3 * P)
    log.foreign_sync(3 * P + 0.0001)
    _answer(log, 3 * P + 0.0003, 99)     # answers the foreign SYNC (the newest it handled)
    assert log.verdict(1, 3).reason == NO_ANSWER


def test_the_exact_sync_time_moves_a_frame_to_the_window_it_belongs_to():
    """The SYNC is logged when sent and again with its end of frame: an answer of the SYNC
    before that ended in between belongs to the window before."""
    log = StationLog(BOUND)
    _steady(log, 2)
    log.sync(3, 3 * P)
    _answer(log, 3 * P + 0.0001, 2, gap=0.00005)  # handled late: 2's second answer?
    log.sync(3, 3 * P + 0.0002)                   # no: SYNC 3 ended after it
    assert log.verdict(1, 3).reason == NO_ANSWER
    assert log.verdict(1, 2).reason == SURPLUS    # window 2 now holds two answers


def test_an_unknown_sync_and_the_settled_share():
    log = StationLog(BOUND)
    assert log.verdict(1, 7).reason == UNKNOWN_SYNC
    assert log.settled(1, 7) is None
    _steady(log, 3)
    assert log.settled(1, 3) == (3 * P, 0.0)
    log.sync(4, 4 * P)
    log.image(1, 4 * P + 0.0003, IMG, 0)
    assert log.settled(1, 4) == (4 * P, 0.5)


def test_a_slot_that_missed_a_window_puts_the_whole_station_out_of_step():
    """Rule 3 asks every slot of the station: one slot's gap means the station's answers of
    that window may be spread over the next, for the other slots too."""
    log = StationLog(BOUND, slots=(1, 2))
    for k in range(1, 5):
        log.sync(k, k * P)
        _answer(log, k * P + 0.0002, k, slot=1)
        if k != 2:
            _answer(log, k * P + 0.0004, k, slot=2)
    assert log.verdict(1, 3).reason == UNSETTLED
    assert log.verdict(2, 3).reason == UNSETTLED
    assert log.verdict(1, 4).reason == UNSETTLED   # window 2 is still one of the two before
    log.sync(5, 5 * P)
    for slot in (1, 2):
        _answer(log, 5 * P + 0.0002 * slot, 5, slot=slot)
    assert log.verdict(1, 5).sample is not None and log.verdict(2, 5).sample is not None


def test_answers_that_spill_over_the_next_sync_are_never_vouched_for():
    """Eight slots' answer takes longer on the wire than the SYNCs of another producer leave
    it (000 Table 15: one image per slot, one position TPDO per two slots): each window holds
    the tail of one answer and the head of the next, so a slot may find one image and one
    position in a window, from two different answers, latched before the SYNC."""
    slots = tuple(range(1, 9))
    log = StationLog(0.005, slots=slots)
    frame = 0.00021
    t, seq = 0.0, 0
    pending: list[tuple[int, str, int]] = []   # (slot, kind, value of the answer's latch)
    for j in range(60):                        # a SYNC every 1 ms, every 5th one the master's
        t_sync = j * 0.001
        if j % 5 == 0:
            seq += 1
            log.sync(seq, t_sync)
        else:
            log.foreign_sync(t_sync)
        t = max(t, t_sync)
        pending += [(s, "image", j) for s in slots] + [(s, "position", j) for s in slots]
        while pending and t + frame < t_sync + 0.001:   # the wire until the next SYNC
            slot, kind, value = pending.pop(0)
            t += frame
            if kind == "image":
                log.image(slot, t, IMG, 0)
            else:
                log.position(slot, t, value)
    vouched = [v for k in range(1, seq + 1) for slot in slots
               if (v := log.verdict(slot, k)).sample is not None]
    assert vouched == []


def test_the_bound_must_be_positive():
    with pytest.raises(ValueError, match="latch_bound"):
        StationLog(0.0)
