"""A joint's health: counters, the level of one status byte, the windowed, debounced level.

ROS-free; the levels are the values of ``diagnostic_msgs/DiagnosticStatus`` (OK 0, WARN 1,
ERROR 2, STALE 3), so ``ros/diagnostics.py`` puts them into messages unchanged. Its ``level``
field is a ROS ``byte``, one-byte :class:`bytes` in Python, so a :data:`Level` is one byte too;
one-byte values order as their numbers do (``OK < WARN < ERROR < STALE``, ``max`` the worst).

Level mapping (docs/node.md has the table):

=================================================  =========
condition                                           level
=================================================  =========
no fresh sample for ``stale_cycles`` cycles          STALE
>= 50 % of the SYNCs of the last 0.5 s stale         ERROR
ERR_PARA (invalid REG_PARA1) or ERR_SSI (wire)       ERROR
>= 10 % of the SYNCs of the last 0.5 s stale         WARN
a jump beyond ``max_speed`` in the last 0.5 s        WARN
STS_OFLW / STS_UFLW (limits), SSI_DIAG, STS_STOP     WARN
otherwise                                           OK
=================================================  =========

A joint's published level is debounced (:class:`ChannelHealth`): STALE rises at once when
nothing at all of the joint came for ``stale_cycles`` cycles (that count is its debounce);
any other level, and STALE from lossy cycles, rises once the condition has held for
``RAISE_AFTER_S`` and falls once the better level has held for ``CLEAR_AFTER_S``,
so a load hiccup shorter than RAISE_AFTER_S never shows and a level can fall only after the
better level held CLEAR_AFTER_S; a WARN/ERROR that flaps is confirmed by its share of the
cycles (:data:`FLAP_SHARE`). The window and the debounce run on SYNC wire time, and every
SYNC sent counts (one the node never handled as lost), so load does not thin the window.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Final, NewType

from ssi_bridge.protocol.frame_check import FrameVerdict
from ssi_bridge.protocol.images import ModuleStatus, ProcessInput

#: a diagnostic level: the one-byte value of ``diagnostic_msgs/DiagnosticStatus.level``
Level = NewType("Level", bytes)
#: the diagnostic levels, as diagnostic_msgs/DiagnosticStatus names them
OK: Final = Level(b"\x00")
WARN: Final = Level(b"\x01")
ERROR: Final = Level(b"\x02")
STALE: Final = Level(b"\x03")


@dataclass
class ChannelCounters:
    """Per-joint counters the node keeps between diagnostics messages."""

    samples: int = 0
    stale_cycles: int = 0
    consecutive_stale: int = 0
    error_cycles: int = 0
    handshake_failures: int = 0
    #: samples whose step from the previous one exceeded ``<joint>.max_speed``
    implausible: int = 0
    #: samples that arrived but could not be vouched for as latched at their SYNC (a backlog,
    #: an answer later than latch_bound, a station not in step): left out, never published
    set_aside: int = 0
    #: why the joint was left out of the last cycle ("" when it was published)
    last_reason: str = ""
    #: cycles in a row in which nothing at all of the joint arrived
    consecutive_silent: int = 0
    #: the latest 8-byte process input image (decoded only when a status is built)
    last_image: bytes | None = None
    last_position: int = 0
    #: cycles whose frame failed the parity / filler check, and the latest verdict
    #: (None when the latest image carried no checked frame)
    frame_errors: int = 0
    frame: FrameVerdict | None = None

    @property
    def last_input(self) -> ProcessInput | None:
        """The latest process input image, decoded."""
        return ProcessInput.decode(self.last_image) if self.last_image is not None else None

    @property
    def last_sts(self) -> int | None:
        """Byte 7 of the latest image (STS_STOP, ERR_PARA, ... SSI_DIAG), None before one."""
        return self.last_image[7] if self.last_image is not None else None


_WARN_BITS = (
    (int(ModuleStatus.STS_OFLW), "STS_OFLW: above REG_UPPER_LIMIT"),
    (int(ModuleStatus.STS_UFLW), "STS_UFLW: below REG_LOWER_LIMIT"),
    (int(ModuleStatus.SSI_DIAG), "SSI_DIAG: an enabled encoder status bit is set"),
    (int(ModuleStatus.STS_STOP), "STS_STOP: acquisition stopped by STOP"),
)
_WARN_MASK = sum(bit for bit, _ in _WARN_BITS)
_ERR_PARA, _ERR_SSI = int(ModuleStatus.ERR_PARA), int(ModuleStatus.ERR_SSI)


def channel_level(sts: int | None, consecutive_stale: int, stale_limit: int
                  ) -> tuple[Level, str]:
    """Level and one-line message of a joint channel from byte 7 of its process input.

    Plain int tests: this runs every cycle for every joint.

    :param sts: byte 7 (status) of the latest process input image; None before any sample
    :param consecutive_stale: SYNC cycles in a row without a fresh sample
    :param stale_limit: from this many such cycles on the channel is STALE
    :returns: the level (OK, WARN, ERROR or STALE) and its one-line message
    """
    if sts is None:
        return STALE, "no sample received yet"
    if consecutive_stale >= stale_limit:
        return STALE, f"no fresh sample for {consecutive_stale} cycles"
    if sts & _ERR_PARA:
        return ERROR, "ERR_PARA: the module rejected REG_PARA1, encoder not read"
    if sts & _ERR_SSI:
        return ERROR, "ERR_SSI: SSI encoder signal faulty (wire break or no data)"
    if sts & _WARN_MASK:
        return WARN, "; ".join(text for bit, text in _WARN_BITS if sts & bit)
    return OK, "reading"


#: window (s) of SYNC wire time over which the stale ratio and implausible jumps are counted
RATIO_WINDOW_S = 0.5
#: stale ratio (lost share of the SYNCs in the window) at or above which a joint is WARN / ERROR
STALE_RATIO_WARN = 0.10
STALE_RATIO_ERROR = 0.50
#: the ratio counts only over at least this many SYNCs, and from 2 windows after the first
#: sample on (the cycles of the start-up say little about the link)
MIN_WINDOW_CYCLES = 10
#: a worse level is published once it held this long; a better one once it held this long
RAISE_AFTER_S = 0.1
CLEAR_AFTER_S = 1.0
#: a WARN or ERROR that flaps (present in some cycles, absent in others) is confirmed too once
#: it was the raw level in at least this share of the cycles of the last RAISE_AFTER_S and its
#: cycles span at least half of that time: an encoder error bit in 40 % of the cycles shows
#: within about RAISE_AFTER_S, a load hiccup (a short run of cycles) still never does
FLAP_SHARE = 0.25
#: at least this many cycles in the window for the flap rule (at low rates the run rule holds)
FLAP_MIN_CYCLES = 4


class ChannelHealth:
    """One joint's level over time: stale ratio and jumps over a window, debounced changes.

    The window is wire time of the SYNCs, and its denominator is the SYNCs sent, not the
    cycles the node got round to: :meth:`observe` takes the SYNC's wire time and sequence
    number, and a SYNC the node never observed (a gap in the sequence) counts as wholly lost.
    So a loaded node that handles fewer cycles sees the same ratio as the wire has, instead
    of a thinned window. Each observed SYNC counts the share of the joint's data of that SYNC
    that did not arrive (``lost``: 0, 1, or 1/2 for one of its two TPDOs).

    :meth:`observe` runs every cycle (cheap: a deque of the window's SYNCs and a short list of
    level changes); :attr:`level` / :attr:`message` are what the diagnostics publish.

    :param window_s: length (s of wire time) of the window the stale ratio and jumps count over
    :param raise_after_s: how long a worse level must hold before it is published
    :param clear_after_s: how long a better level must hold before the published one falls
    """

    def __init__(self, window_s: float = RATIO_WINDOW_S, raise_after_s: float = RAISE_AFTER_S,
                 clear_after_s: float = CLEAR_AFTER_S) -> None:
        self.window_s = window_s
        self.raise_after_s = raise_after_s
        self.clear_after_s = clear_after_s
        #: (SYNC wire time, lost share, SYNCs, implausible) per observed SYNC (or gap of them)
        self._syncs: deque[tuple[float, float, int, bool]] = deque()
        self.lost_in_window = 0.0
        self.syncs_in_window = 0
        self.jumps_in_window = 0
        #: the last observed SYNC (sequence number, wire time), for the gaps
        self._last_seq: int | None = None
        self._last_t = 0.0
        #: the raw level once a rise held RAISE_AFTER_S (falls at once)
        self._confirmed = STALE
        #: time of the first sample (the stale ratio counts from two windows after it)
        self._first_t: float | None = None
        #: a sample has been seen (before it, STALE "no sample received yet" is no condition)
        self._sampled = False
        #: (since, lowest raw level) while the raw level is above ``_confirmed``
        self._up: tuple[float, Level] | None = None
        #: the flap rule's window, the last RAISE_AFTER_S: the times of all its cycles, and of
        #: those whose raw level was ERROR / WARN or ERROR (running, so a cycle costs O(1))
        self._recent: deque[float] = deque()
        self._recent_error: deque[float] = deque()
        self._recent_warn: deque[float] = deque()
        #: (time, confirmed level) at each change, back to the one in force CLEAR_AFTER_S ago
        self._history: deque[tuple[float, Level]] = deque()
        self.level = STALE
        self._silent = False
        self.message = "no sample received yet"
        self._messages: dict[Level, str] = {STALE: self.message}

    @property
    def stale_ratio(self) -> float:
        """Lost share of the SYNCs of the window (0 before any SYNC)."""
        return self.lost_in_window / self.syncs_in_window if self.syncs_in_window else 0.0

    def observe(self, now: float, *, stale: bool, implausible: bool, sts: int | None,
                consecutive_stale: int, stale_limit: int, seq: int | None = None,
                lost: float | None = None, silent: bool = False) -> Level:
        """Count one SYNC and return the debounced level.

        :param now: wire time of the SYNC (the window's clock)
        :param stale: no complete fresh sample of this SYNC
        :param implausible: this SYNC's sample was an implausible jump (counted in the window)
        :param sts: byte 7 of the latest process input image (None before any), as
            :func:`channel_level` takes it
        :param consecutive_stale: SYNC cycles in a row without a fresh sample
        :param stale_limit: from this many such cycles on the raw level is STALE
        :param seq: the SYNC's sequence number; SYNCs skipped since the last one count lost
        :param lost: the share of the joint's data of this SYNC that is missing (default:
            all of it when ``stale``)
        :param silent: nothing at all of the joint came for ``stale_limit`` cycles in a row
            (STALE is then published without the rise debounce)
        :returns: the debounced level, also in :attr:`level` (its text in :attr:`message`)
        """
        self._silent = silent
        if lost is None:
            share = 1.0 if stale else 0.0
        else:
            share = lost if 0.0 <= lost <= 1.0 else min(max(lost, 0.0), 1.0)
        syncs = self._syncs
        # the window's sums in locals (the same additions in the same order), stored once
        lost_sum, n, jumps = self.lost_in_window, self.syncs_in_window, self.jumps_in_window
        if seq is not None:
            last = self._last_seq
            if last is not None and seq > last + 1:
                missed = seq - last - 1  # SYNCs on the wire that the node never handled
                syncs.append((0.5 * (self._last_t + now), float(missed), missed, False))
                lost_sum += missed
                n += missed
            self._last_seq = seq
        self._last_t = now
        syncs.append((now, share, 1, implausible))
        lost_sum += share
        n += 1
        jumps += implausible
        horizon = now - self.window_s
        while syncs and syncs[0][0] < horizon:
            _t, was_lost, count, was_jump = syncs.popleft()
            lost_sum -= was_lost
            n -= count
            jumps -= was_jump
        if not syncs:
            lost_sum = 0.0  # no float residue once the window empties
        self.lost_in_window, self.syncs_in_window, self.jumps_in_window = lost_sum, n, jumps
        raw, message = channel_level(sts, consecutive_stale, stale_limit)
        ratio = lost_sum / n if n else 0.0
        if self._first_t is None and sts is not None:
            self._first_t = now
        settled = self._first_t is not None and now - self._first_t >= 2 * self.window_s
        if raw != STALE and settled and n >= MIN_WINDOW_CYCLES:
            if ratio >= STALE_RATIO_ERROR and raw < ERROR:
                raw, message = ERROR, self._ratio_text(ratio, n)
            elif ratio >= STALE_RATIO_WARN and raw < WARN:
                raw, message = WARN, self._ratio_text(ratio, n)
            elif self.jumps_in_window and raw < WARN:
                raw, message = WARN, (f"position jumped faster than max_speed "
                                      f"({self.jumps_in_window} sample(s) in the last "
                                      f"{self.window_s:g} s)")
        self._messages[raw] = message
        return self._debounce(now, raw)

    def _ratio_text(self, ratio: float, n: int) -> str:
        return (f"{ratio:.0%} of the last {n} SYNCs' data stale or lost ({self.window_s:g} s "
                f"of wire time; WARN from {STALE_RATIO_WARN:.0%}, ERROR from "
                f"{STALE_RATIO_ERROR:.0%})")

    def _flapping(self, now: float, raw: Level) -> Level | None:
        """The worst WARN/ERROR that flaps in the last RAISE_AFTER_S (:data:`FLAP_SHARE` of its
        cycles, spanning half of it), or None. Its message says in how many cycles.

        Runs every cycle for every joint: the window keeps the times of its ERROR and of its
        WARN-or-worse cycles apart, so no cycle scans the window.
        """
        recent, errors, warns = self._recent, self._recent_error, self._recent_warn
        recent.append(now)
        if WARN <= raw < STALE:
            warns.append(now)
            if raw >= ERROR:
                errors.append(now)
        horizon = now - self.raise_after_s
        while recent and recent[0] < horizon:
            recent.popleft()
        if not warns:
            return None  # as a rule: no WARN nor ERROR (a subset of them) in the window
        for times in (warns, errors):
            while times and times[0] < horizon:
                times.popleft()
        n = len(recent)
        if n < FLAP_MIN_CYCLES or self.raise_after_s <= 0 or not warns:
            return None
        for level, times in ((ERROR, errors), (WARN, warns)):
            if (times and len(times) >= FLAP_SHARE * n
                    and times[-1] - times[0] >= 0.5 * self.raise_after_s):
                # the worst raw level of the window at or above ``level`` (below STALE)
                worst = ERROR if errors else level
                text = self._messages.get(worst, "").split(" (in ")[0]
                self._messages[worst] = f"{text} (in {len(times)} of the last {n} cycles)"
                return worst
        return None

    def _debounce(self, now: float, raw: Level) -> Level:
        """Two stages. ``confirmed`` follows the raw level down at once but up only when the
        worse level held RAISE_AFTER_S (a load hiccup never confirms it). The published level
        follows ``confirmed`` up at once and down to the worst confirmed level of the last
        CLEAR_AFTER_S, so it falls only when the better level held that long."""
        if not self._sampled:
            if raw == STALE:
                return self.level  # still no sample: nothing to debounce yet
            # the first sample: "no sample yet" is no condition to hold on to
            self._sampled = True
            self._confirmed = self.level = raw
            self._history.append((now, raw))
            self.message = self._messages[raw]
            return raw
        confirmed = self._confirmed
        flapped = self._flapping(now, raw)
        if flapped is None and raw == confirmed == self.level and len(self._history) == 1:
            # steady (as a rule every cycle): nothing rises, falls or is remembered
            self._up = None
            self.message = self._messages.get(raw, self.message)
            return raw
        if flapped is not None and flapped > confirmed:
            confirmed, raw, self._up = flapped, flapped, None
        elif raw < confirmed:
            confirmed, self._up = raw, None
        elif raw == STALE and raw > confirmed and self._silent:
            # nothing at all of the joint for ``stale_cycles`` cycles in a row (a silent or
            # stalled station, a cable pulled): that count is the debounce already, and a
            # left-out joint must say so within 0.2 s (docs/node.md). Lossy cycles that left
            # it out keep the debounce: bursts of loss would flap it
            confirmed, self._up = STALE, None
        elif raw > confirmed:
            if self._up is None:
                self._up = (now, raw)
            elif raw < self._up[1]:
                self._up = (self._up[0], raw)
            if now - self._up[0] >= self.raise_after_s:
                confirmed, self._up = self._up[1], None
        else:
            self._up = None
        history = self._history
        if confirmed != self._confirmed or not history:
            history.append((now, confirmed))
        self._confirmed = confirmed
        horizon = now - self.clear_after_s
        while len(history) > 1 and history[1][0] <= horizon:
            history.popleft()  # history[0] stays the level in force at the horizon
        if confirmed > self.level:
            self.level = confirmed
        elif confirmed < self.level and history[0][0] <= horizon:
            worst = max(level for _t, level in history)
            if worst < self.level:
                self.level = worst
        self.message = self._messages.get(self.level, self.message)
        return self.level
