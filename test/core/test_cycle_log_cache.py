"""StationLog keeps rule 3's answer per SYNC until a frame or SYNC within its windows changes:
the cached answers must be the ones a fresh computation gives, whatever arrives in between.

Two logs are fed the same random traffic (the master's SYNCs, some re-timed as the master does
once the wire gives the exact time, another producer's SYNCs now and then, late, missing,
doubled and out-of-order frames); each step one of them is asked about recent SYNCs through its
cache (prepare, verdicts, settled) and the other with its cache emptied before every question.
Every verdict (reason, sample) must agree.
"""

from __future__ import annotations

import random

from ssi_bridge.core.cycle_log import KEEP_SYNCS, StationLog

PERIOD = 0.001
SLOTS = (1, 2, 3)


def _feed(logs: list[StationLog], rng: random.Random, k: int, t: float) -> None:
    estimate = t - 0.00002
    for log in logs:
        log.sync(k, estimate)
    if rng.random() < 0.9:
        for log in logs:
            log.sync(k, t)  # the exact time, once the wire gave it
    if rng.random() < 0.03:
        for log in logs:
            log.foreign_sync(t + 0.0005)
    for slot in SLOTS:
        r = rng.random()
        if r < 0.04:
            continue
        delay = 0.0001 * slot + (0.0012 if r < 0.08 else 0.0)  # now and then late
        image = bytes([k & 0xFF, slot, 0, 0, 0, 0, 0, 0])
        copies = 2 if r > 0.97 else 1
        for _ in range(copies):
            for log in logs:
                log.image(slot, t + delay, image, k)
        if r < 0.1:
            continue  # partial
        for log in logs:
            log.position(slot, t + delay + 0.00003, k * slot)
    if rng.random() < 0.05 and k > 3:  # a frame of an older window handled late
        for log in logs:
            log.position(1, t - 1.5 * PERIOD, 7)


def _fresh(log: StationLog) -> StationLog:
    log._in_step.clear()  # noqa: SLF001 - the reference computes every answer afresh
    return log


def test_cached_rule_3_answers_are_the_fresh_ones() -> None:
    rng = random.Random(33)
    cached = StationLog(0.0004, slots=SLOTS)
    fresh = StationLog(0.0004, slots=SLOTS)
    vouched = 0
    for k in range(1, KEEP_SYNCS + 200):  # past the SYNCs the log keeps
        t = k * PERIOD
        _feed([cached, fresh], rng, k, t)
        if rng.random() < 0.5:
            cached.prepare(k)
        for seq in (k, k - 1, k - 2):
            got = cached.verdicts(SLOTS, seq)
            want = [_fresh(fresh).verdict(slot, seq) for slot in SLOTS]
            assert [(v.reason, v.sample) for v in got] == \
                [(v.reason, v.sample) for v in want], (k, seq)
            assert cached.settled_all(SLOTS, seq) == [_fresh(fresh).settled(s, seq)
                                                      for s in SLOTS]
            vouched += sum(v.sample is not None for v in got)
    assert vouched > 300, "the traffic must let samples through, or nothing is compared"
