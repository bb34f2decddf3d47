"""Which SYNC a station's TPDOs answer, decided from wire times alone: the station's frame log.

ROS-free and free of any bus library: the master hands every event of one station to a
:class:`StationLog` (the master's ``FrameSink``: its own SYNC with sequence number and wire
time, another producer's SYNC, each process input image and each position of a slot with its
wire time), and the cycle asks :meth:`StationLog.verdict` whether a slot's sample can be
vouched for as latched at the stamp of one of the master's SYNCs.

The rule (docs/node.md, "Which cycle a TPDO answers"). Every SYNC on the wire, the master's or
another producer's, opens a *window* that lasts until the next SYNC. A station answers each
SYNC it handles with one image and one position per slot (000 Table 15, transmission type 1),
latched when it handles the SYNC, and sends them after that. A slot's sample counts for the
master's SYNC ``k`` (wire time ``t_k``) only when

1. the window of ``k`` holds exactly one image and one position of the slot (none: not
   answered; one kind only: partial; more: a backlog, so the first is not ``k``'s answer);
2. the earlier of the two ended on the wire at most ``latch_bound`` after ``t_k``: the station
   latched when it handled the SYNC, after ``t_k`` and before it sent either frame, so the
   sample is the encoder's position at ``t_k`` within ``latch_bound`` of motion (the node's
   bound is the gateway's reaction allowance plus the cycle's wire time, since a slot's frames
   may wait behind the other slots' on the wire);
3. the two windows before ``k`` are the master's own (no other producer's SYNC since the SYNC
   two before ``k``) and in each of them *every* slot of the station got exactly one image and
   one position, the first within ``latch_bound`` of that window's SYNC: the station was in
   step when ``k`` came. Between another producer's SYNCs a station saturated by them can
   stay one answer behind with every answer looking prompt; a full period of the master's
   own is long enough that it cannot. A station that missed a window, or
   answered it late or only in part, may still owe an answer, whose frames would be the first
   after ``t_k``; and a station whose answers spill over the next SYNC (a wire too busy for
   them) mixes frames of several answers in one window, which a slot alone cannot see.

Anything else is *set aside* with a reason (:data:`REASONS`); the cycle leaves the joint out.
A station that stays exactly one SYNC behind for good, with on-time-looking answers, cannot be
told from one in step on the wire: docs/node.md says so.
"""

from __future__ import annotations

import math
import threading
from bisect import bisect_left, insort
from collections import deque
from collections.abc import Sequence

from ssi_bridge.core.frame_window import AT as _T
from ssi_bridge.core.frame_window import COUNT as _COUNT
from ssi_bridge.core.frame_window import IMAGE, POSITION, Frame, all_answered_once
from ssi_bridge.core.frame_window import IMAGE_BYTES as _IMAGE
from ssi_bridge.core.frame_window import KIND as _KIND
from ssi_bridge.core.frame_window import VALUE as _POSITION
from ssi_bridge.core.verdict import Answer, Verdict, VouchedSample

#: why a sample was set aside, as the diagnostics and ``~/status`` say it
NO_ANSWER = "no answer"
PARTIAL = "partial answer"
SURPLUS = "more than one answer (a backlog)"
LATE = "answer later than latch_bound"
UNSETTLED = "station not in step with the SYNC before"
UNKNOWN_SYNC = "SYNC not in the log"
REASONS = (NO_ANSWER, PARTIAL, SURPLUS, LATE, UNSETTLED, UNKNOWN_SYNC)
#: SYNCs (own and foreign) and frames per slot the log keeps: far more than two windows of
#: the densest traffic the wire carries between two cycles of the master
KEEP_SYNCS = 256
KEEP_FRAMES = 256


#: the answer of every slot at a SYNC the log does not hold
_UNKNOWN: Answer = (None, UNKNOWN_SYNC, 1.0, b"", None)


class StationLog:
    """The frame log of one station; the master feeds it, the cycle asks it.

    Thread-safe: the master's receive thread feeds it while the cycle thread asks.

    :param latch_bound: the longest a slot's frames may end after the SYNC (s) for the
        sample to count as latched at the SYNC (rule 2 of the module docstring)
    :param slots: the slots of the station the master reads (rule 3 asks all of them)
    :param history: windows before the SYNC in which the station must have been in step
    :raises ValueError: ``latch_bound`` not > 0, no slots, ``history`` < 1
    """

    def __init__(self, latch_bound: float, slots: tuple[int, ...] = (1,),
                 history: int = 2) -> None:
        if not latch_bound > 0:
            raise ValueError(f"latch_bound {latch_bound} s must be > 0")
        if history < 1:
            raise ValueError(f"history {history} must be >= 1 window")
        if not slots:
            raise ValueError("a station log needs the slots that answer (1-8)")
        self.latch_bound = latch_bound
        #: the station's slots that the master reads: each answers every SYNC it handles
        self.slots = tuple(sorted(set(slots)))
        #: t_k -> (wire time of the first of its windows, -inf when there are fewer; whether
        #: the station was in step before t_k), for the SYNCs asked about lately: a cycle asks
        #: about its SYNC and, for the health, the one before. An answer stands until a frame
        #: or a SYNC within its windows changes (:meth:`_forget`)
        self._in_step: dict[float, tuple[float, bool]] = {}
        #: the wire times those answers' windows span, from the earliest first SYNC to the
        #: latest SYNC asked about (empty: inf, -inf): a frame outside changes none of them
        self._span = (math.inf, -math.inf)
        #: windows before the SYNC that must show the station in step (rule 3)
        self.history = history
        self._lock = threading.Lock()
        #: wire times of every SYNC on the bus (own and foreign), ascending
        self._syncs: list[float] = []
        #: the master's own SYNCs: sequence number -> wire time
        self._own: dict[int, float] = {}
        self._own_order: deque[int] = deque()
        #: the wire times of the master's own SYNCs in the log (rule 3's windows are theirs)
        self._own_times: set[float] = set()
        self._frames: dict[int, deque[Frame]] = {}

    # -- the master's side (client.samples.FrameSink) ---------------------------------------
    def sync(self, seq: int, t: float) -> None:
        """The master's SYNC ``seq`` is (or, called again, was exactly) at wire time ``t``."""
        with self._lock:
            old = self._own.get(seq)
            if old is not None:
                i = bisect_left(self._syncs, old)
                if i < len(self._syncs) and self._syncs[i] == old:
                    del self._syncs[i]
                self._own_times.discard(old)
                self._forget(old)
            else:
                self._own_order.append(seq)
                if len(self._own_order) > KEEP_SYNCS:
                    gone = self._own.pop(self._own_order.popleft(), None)
                    if gone is not None:
                        self._own_times.discard(gone)
                        self._forget(gone)
            self._own[seq] = t
            self._own_times.add(t)
            self._insert(t)

    def foreign_sync(self, t: float) -> None:
        """Another producer's SYNC ended on the wire at ``t``: it opens a window too."""
        with self._lock:
            self._insert(t)

    def image(self, slot: int, t: float, data: bytes | bytearray, count: int) -> None:
        """A process input image of ``slot`` (its 8 bytes ``data``; ``count``: images received
        for the slot so far, this one included) ended on the wire at ``t`` (s)."""
        frame = (t, IMAGE, data if type(data) is bytes else bytes(data), 0, count)
        with self._lock:
            self._append(slot, frame)

    def position(self, slot: int, t: float, value: int) -> None:
        """A position of ``slot`` (REG_SSI_POS ``value`` as received) ended on the wire at
        ``t`` (s)."""
        with self._lock:
            self._append(slot, (t, POSITION, b"", value, 0))

    def positions(self, slots: Sequence[int], t: float, values: Sequence[int]) -> None:
        """:meth:`position` of each of ``slots``, all ended on the wire at ``t`` (s), with the
        value of ``values`` at the same index (one encoder default PDO carries several)."""
        with self._lock:
            for slot, value in zip(slots, values):
                self._append(slot, (t, POSITION, b"", value, 0))

    def _insert(self, t: float) -> None:
        syncs = self._syncs
        if not syncs or t >= syncs[-1]:
            syncs.append(t)
        else:
            insort(syncs, t)
        self._forget(t)
        if len(syncs) > KEEP_SYNCS:
            gone = len(syncs) - KEEP_SYNCS
            self._forget(syncs[gone - 1])
            del syncs[:gone]

    def _append(self, slot: int, frame: Frame) -> None:
        """Under the lock: keep ``frame`` of ``slot`` (the oldest falls out of a full log)."""
        frames = self._frames.get(slot)
        lo, hi = self._span
        if frames is None:
            frames = self._frames[slot] = deque(maxlen=KEEP_FRAMES)
        elif len(frames) == KEEP_FRAMES and lo <= frames[0][_T] <= hi:
            self._forget(frames[0][_T])  # about to fall out
        t = frame[_T]
        if lo <= t <= hi:  # as a rule a frame answers the newest SYNC: after them all
            self._forget(t)
        frames.append(frame)

    def _forget(self, t: float) -> None:
        """Under the lock: a frame or SYNC at wire time ``t`` came or went: drop the rule-3
        answers whose windows (from the first one's SYNC to the SYNC asked about) hold ``t``.
        A frame after the SYNC asked about, or a SYNC after it, changes no answer."""
        cache = self._in_step
        if cache:
            stale = [key for key, (first, _ok) in cache.items() if first <= t <= key]
            for key in stale:
                del cache[key]
            if stale:
                self._spanned()

    def _spanned(self) -> None:
        """Under the lock: :attr:`_span` after the cached answers changed."""
        c = self._in_step
        self._span = (min(c.values())[0], max(c)) if c else (math.inf, -math.inf)

    # -- the cycle's side -------------------------------------------------------------------
    def sync_time(self, seq: int) -> float | None:
        """The wire time of the master's SYNC ``seq`` (None: not in the log)."""
        with self._lock:
            return self._own.get(seq)

    def verdict(self, slot: int, seq: int) -> Verdict:
        """Whether ``slot``'s sample of the master's SYNC ``seq`` is vouched for (see module)."""
        return self.verdicts((slot,), seq)[0]

    def verdicts(self, slots: Sequence[int], seq: int) -> list[Verdict]:
        """:meth:`verdict` of each of ``slots`` at the master's SYNC ``seq``, in that order:
        the SYNC looked up and rule 3 asked once for all of them."""
        return [Verdict(*answer) for answer in self.answers(slots, seq)]

    def answers(self, slots: Sequence[int], seq: int) -> list[Answer]:
        """:meth:`verdicts` of ``slots`` at the master's SYNC ``seq`` as plain tuples
        (:data:`Answer`), for the cycle on the receive thread: no instance per slot."""
        t_k, answers = self._judged(slots, seq, vouch=True)
        return answers if t_k is not None else [_UNKNOWN] * len(slots)

    def _judged(self, slots: Sequence[int], seq: int, vouch: bool
                ) -> tuple[float | None, list[Answer]]:
        """Rules 1-3 for each of ``slots`` at the master's SYNC ``seq``, one pass over each
        slot's window: (the SYNC's wire time, None when not in the log; per slot its answer,
        the sample left out (None) unless ``vouch``)."""
        out: list[Answer] = []
        with self._lock:
            t_k = self._own.get(seq)
            if t_k is None:
                return None, out
            syncs = self._syncs
            i = bisect_left(syncs, t_k)
            t_next = syncs[i + 1] if i + 1 < len(syncs) else math.inf
            in_step = self._station_in_step(t_k, i)
            get = self._frames.get
            bound = self.latch_bound
            append = out.append
            for slot in slots:
                images = positions = 0
                img: Frame | None = None
                pos: Frame | None = None
                frames: Sequence[Frame] = get(slot, ())
                j = len(frames) - 1
                while j > 1 and frames[j][_T] >= t_next:
                    j -= 1  # a later window's (the health asks about the SYNC before)
                if j > 1:  # as a rule the two newest frames left are the window's two
                    a, b = frames[j], frames[j - 1]
                    if (t_k <= a[_T] and t_k <= b[_T] < t_next  # a[_T] < t_next: above
                            and frames[j - 2][_T] < t_k and a[_KIND] != b[_KIND]):
                        images = positions = 1
                        img, pos = (a, b) if a[_KIND] == IMAGE else (b, a)
                if not images:  # the window's frames, newest first, as they are
                    for f in reversed(frames):
                        t = f[_T]
                        if t < t_k:
                            break
                        if t < t_next:
                            if f[_KIND] == IMAGE:
                                images += 1
                                if img is None:
                                    img = f
                            else:
                                positions += 1
                                if pos is None:
                                    pos = f
                if img is None or pos is None:
                    append((None, NO_ANSWER if img is None and pos is None else PARTIAL,
                            ((img is None) + (pos is None)) / 2,
                            img[_IMAGE] if img is not None else b"",
                            pos[_POSITION] if pos is not None else None))
                    continue
                image, value = img[_IMAGE], pos[_POSITION]
                t_img, t_pos = img[_T], pos[_T]
                delay = (t_img if t_img < t_pos else t_pos) - t_k
                if images > 1 or positions > 1:
                    reason = SURPLUS
                elif delay > bound:
                    reason = LATE
                elif in_step:  # vouched for
                    append((VouchedSample(slot, value, image, t_k, img[_COUNT], delay)
                            if vouch else None, "", 0.0, image, value))
                    continue
                else:
                    reason = UNSETTLED
                append((None, reason, 0.0, image, value))
        return t_k, out

    def _station_in_step(self, t_k: float, i: int) -> bool:
        """Rule 3 for the SYNC at ``t_k`` (index ``i`` of the SYNCs), under the lock: in each
        of the ``history`` windows before it, every slot of the station answered exactly once
        (one image, one position), the first frame within ``latch_bound`` of the window's
        SYNC. A station whose answer spills over a SYNC (a wire too busy for its answers, a
        late or partial answer) is out of step, for all its slots: a slot's frames of one
        window may then belong to different answers. Computed once per SYNC, again only when
        a frame or SYNC within its windows came or went since (:meth:`_forget`).
        """
        cache = self._in_step
        cached = cache.get(t_k)
        if cached is not None:
            return cached[1]
        back = self.history
        bounds = self._syncs[max(i - back, 0): i + 1]
        # the windows are the master's own: with another producer's SYNC among them, a
        # station saturated by SYNCs can stay one answer behind, each answer looking prompt
        own = self._own_times
        ok = (len(bounds) == back + 1 and own.issuperset(bounds)
              and self._all_answered_once(bounds))
        if len(cache) >= 4:
            del cache[min(cache)]
        cache[t_k] = (bounds[0] if len(bounds) == back + 1 else -math.inf, ok)
        self._spanned()
        return ok

    def prepare(self, seq: int) -> None:
        """Ask rule 3 for the master's SYNC ``seq`` ahead of its verdicts (the cycle thread,
        while the station's answers are on the wire): its windows are over, so the answer
        usually stands when the cycle completes, and the verdicts need not compute it then."""
        with self._lock:
            t_k = self._own.get(seq)
            if t_k is not None:
                self._station_in_step(t_k, bisect_left(self._syncs, t_k))

    def _all_answered_once(self, bounds: list[float]) -> bool:
        """Under the lock: rule 3's scan of the windows between ``bounds``
        (:func:`~ssi_bridge.core.frame_window.all_answered_once`)."""
        return all_answered_once(self._frames, self.slots, bounds, self.latch_bound)

    def settled(self, slot: int, seq: int) -> tuple[float, float] | None:
        """(wire time, share of the slot's answer not vouched) of the master's SYNC ``seq``,
        judged again now that its window is over; None when the SYNC is not in the log.

        What the joint's health counts: a SYNC whose answer was on the wire in time counts as
        answered however late the master handled it; one set aside counts as lost.
        """
        return self.settled_all((slot,), seq)[0]

    def settled_all(self, slots: Sequence[int], seq: int) -> list[tuple[float, float] | None]:
        """:meth:`settled` of each of ``slots``, in that order (one look-up of the SYNC).

        :param slots: the slots asked about
        :param seq: the number of the SYNC whose cycle they belong to
        :returns: per slot, (the SYNC's wire time, the share of the slot's answer not
            vouched: 0.0 when its sample is), or None for each when the SYNC is not in the log
        """
        t, answers = self._judged(slots, seq, vouch=False)
        if t is None:
            return [None] * len(slots)
        # the share of a slot's two TPDOs that never came; all of it for one set aside
        return [(t, 0.0 if not reason else missing or 1.0)
                for _sample, reason, missing, _image, _position in answers]


__all__ = ["IMAGE", "KEEP_FRAMES", "KEEP_SYNCS", "LATE", "NO_ANSWER", "PARTIAL", "POSITION",
           "REASONS", "SURPLUS", "UNKNOWN_SYNC", "UNSETTLED", "Answer", "Frame", "StationLog",
           "Verdict", "VouchedSample"]
