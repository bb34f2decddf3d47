"""StationLog's verdicts against a plain reading of rules 1 and 2 (``core/cycle_log.py``).

The log judges a slot at SYNC ``k`` from the frames of ``k``'s window: from ``t_k`` up to the
next SYNC on the wire (the master's or another producer's), read newest first back to the
first frame before ``t_k``. It takes the common case (the slot's two newest frames are the
window's image and position) without walking the window: the verdicts must be those of the
walk whatever the traffic (late, missing, doubled, out-of-order frames, frames of the next
window already in, another producer's SYNCs). The reference here walks every slot's frames as
fed; rule 3 (the two windows before) is the log's own, so a sample that passes rules 1-2 may
be vouched ("") or set aside as unsettled, and a vouched one must carry the window's frames.
"""

from __future__ import annotations

import random
from bisect import bisect_right

from ssi_bridge.core.cycle_log import (
    LATE, NO_ANSWER, PARTIAL, SURPLUS, UNSETTLED, StationLog,
)

PERIOD = 0.002
BOUND = 0.0006
SLOTS = (1, 2, 3, 4)


def _reference(frames: list[tuple[float, str, int]], t_k: float, t_next: float
               ) -> tuple[str, tuple[float, str, int] | None, tuple[float, str, int] | None]:
    """Rules 1-2 for one slot: (reason or "" for passed, newest image, newest position) of the
    window, walked newest first back to the first frame before ``t_k``."""
    images: list[tuple[float, str, int]] = []
    positions: list[tuple[float, str, int]] = []
    for f in reversed(frames):
        if f[0] < t_k:
            break
        if f[0] < t_next:
            (images if f[1] == "image" else positions).append(f)
    img = images[0] if images else None
    pos = positions[0] if positions else None
    if img is None or pos is None:
        return (NO_ANSWER if img is None and pos is None else PARTIAL), img, pos
    if len(images) > 1 or len(positions) > 1:
        return SURPLUS, img, pos
    if min(img[0], pos[0]) - t_k > BOUND:
        return LATE, img, pos
    return "", img, pos


def test_verdicts_are_those_of_the_window_walk() -> None:
    rng = random.Random(39)
    log = StationLog(BOUND, slots=SLOTS)
    fed: dict[int, list[tuple[float, str, int]]] = {s: [] for s in SLOTS}
    syncs: list[float] = []
    own: dict[int, float] = {}
    checked = {"": 0, "set aside": 0}
    for k in range(1, 400):
        t = k * PERIOD
        log.sync(k, t)
        own[k] = t
        syncs.append(t)
        if rng.random() < 0.05:
            log.foreign_sync(t + 0.0009)
            syncs.append(t + 0.0009)
        for slot in SLOTS:
            r = rng.random()
            if r < 0.02:
                continue  # no answer
            delay = 0.0001 * slot + (0.0008 if r < 0.05 else 0.0)  # now and then late
            kinds = ["image", "position"]
            if r > 0.93:
                kinds.reverse()  # the position first
            if r > 0.98:
                kinds += kinds  # two answers in one window (a backlog)
            if 0.05 <= r < 0.1:
                kinds = [rng.choice(kinds)]  # partial
            for i, kind in enumerate(kinds):
                at = t + delay + 0.00003 * i
                value = k * 10 + slot
                fed[slot].append((at, kind, value))
                if kind == "image":
                    log.image(slot, at, bytes([k & 0xFF, slot, 0, 0, 0, 0, 0, 0]), k)
                else:
                    log.position(slot, at, value)
        if rng.random() < 0.05 and k > 3:  # a frame of an older window, handled late
            fed[1].append((t - 1.5 * PERIOD, "position", 7))
            log.position(1, t - 1.5 * PERIOD, 7)
        for seq in (k, k - 1, k - 2):  # the cycle's question, and the health's
            if seq < 1:
                continue
            t_k = own[seq]
            i = bisect_right(syncs, t_k)
            t_next = syncs[i] if i < len(syncs) else float("inf")
            answers = log.answers(SLOTS, seq)
            for slot, (sample, reason, missing, image, position) in zip(SLOTS, answers):
                want, img, pos = _reference(fed[slot], t_k, t_next)
                where = (k, seq, slot)
                assert position == (pos[2] if pos is not None else None), where
                assert (image != b"") == (img is not None), where
                assert missing == ((img is None) + (pos is None)) / 2, where
                if want:
                    assert reason == want and sample is None, where
                    checked["set aside"] += 1
                    continue
                assert reason in ("", UNSETTLED), where
                if reason == "":
                    assert sample is not None and pos is not None and img is not None
                    assert sample.position == pos[2] and sample.sync_time == t_k, where
                    assert sample.delay == min(img[0], pos[0]) - t_k, where
                    checked[""] += 1
    # the traffic must let samples through and set others aside, or little is compared
    assert checked[""] > 600 and checked["set aside"] > 400, checked
