"""A slot's received TPDOs as the station's frame log keeps them, and rule 3's scan of them.

ROS-free and free of any bus library. The frame log (``core/cycle_log.py``) keeps each slot's
TPDOs as plain tuples (cheaper than instances, on the receive thread) and asks
:func:`all_answered_once` whether the station was in step in the windows before a SYNC (rule
3 of docs/node.md, "Which cycle a TPDO answers"): in each window every slot got exactly one
image and one position, the first of them within ``latch_bound`` of the window's SYNC.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Mapping, Sequence
from typing import Final

#: the kinds of a slot's two TPDOs (000 Table 15: process input image, encoder default PDO)
IMAGE, POSITION = 0, 1

#: one received TPDO of one slot, read through these indices (mypy takes a literal Final as
#: a tuple index):
AT: Final = 0  # wire time (s)
KIND: Final = 1  # IMAGE or POSITION
IMAGE_BYTES: Final = 2  # the 8-byte process input image (IMAGE), else b""
VALUE: Final = 3  # REG_SSI_POS (POSITION), else 0
COUNT: Final = 4  # images received for the slot so far (IMAGE), else 0
Frame = tuple[float, int, bytes, int, int]


def pairs_in_step(frames: Sequence[Frame], bounds: list[float], bound: float) -> bool:
    """Rule 3 for one slot in the common case, without walking its frames.

    :param frames: the slot's frames as they came, oldest first
    :param bounds: the windows' SYNC times, ascending, the last the SYNC asked about
    :param bound: latch_bound (s)
    :returns: True when, past the frames at or after ``bounds[-1]``, the slot's newest frames
        are one image and one position per window, window by window (the newest window's
        two last), the first of each pair within ``bound`` of its SYNC, and the frame before
        them (if any) is older than the first window; False: not that case (the walk of
        :func:`all_answered_once` decides)
    """
    t_k = bounds[-1]
    j = len(frames) - 1
    while j >= 0 and frames[j][AT] >= t_k:
        j -= 1
    w = len(bounds) - 2
    if j < 2 * w + 1:
        return False
    end = t_k
    while w >= 0:
        start = bounds[w]
        a, b = frames[j], frames[j - 1]
        t_a, t_b = a[AT], b[AT]
        if (not start <= t_b <= t_a < end or a[KIND] == b[KIND]
                or (t_a if t_a < t_b else t_b) - start > bound):
            return False
        end = start
        j -= 2
        w -= 1
    return j < 0 or frames[j][AT] < end


def all_answered_once(frames_of: Mapping[int, Sequence[Frame]], slots: Sequence[int],
                      bounds: list[float], bound: float) -> bool:
    """Rule 3's scan: in each window between consecutive ``bounds`` (SYNC times, the last
    one the SYNC asked about), every one of ``slots`` has exactly one image and one position
    in ``frames_of`` (per slot, as they came), the first of them within ``bound`` of the
    window's SYNC. The frames are read newest first, back to the first one before
    ``bounds[0]``."""
    lo, t_k = bounds[0], bounds[-1]
    back = len(bounds) - 1
    for slot in slots:
        frames = frames_of.get(slot, ())
        if pairs_in_step(frames, bounds, bound):
            continue  # as a rule: each window's two frames, newest last, as they came
        inside: list[Frame] = []
        for f in reversed(frames):
            t = f[AT]
            if t >= t_k:
                continue
            if t < lo:
                break
            inside.append(f)
        if len(inside) != 2 * back:  # every window needs exactly its two
            return False
        counts = [0] * (2 * back)  # per window: images, positions
        first = [math.inf] * back
        for f in inside:
            t = f[AT]
            w = bisect_right(bounds, t) - 1
            counts[2 * w + f[KIND]] += 1
            if t < first[w]:
                first[w] = t
        for w in range(back):
            if counts[2 * w] != 1 or counts[2 * w + 1] != 1 or first[w] - bounds[w] > bound:
                return False
    return True


__all__ = ["AT", "COUNT", "IMAGE", "IMAGE_BYTES", "KIND", "POSITION", "VALUE", "Frame",
           "all_answered_once", "pairs_in_step"]
