"""The replay's time line, without ROS: pause, step, rate, seek, and where playback ends.

``replay`` publishes message ``k`` when the time line reaches its log time. The time line is
an anchor (a bag time and the monotonic time it was reached) and a rate: while playing, the
bag time now is ``anchor_bag + (now - anchor_wall) * rate``; while paused it stays at the
anchor. Every control (keyboard, the ``~/pause`` ... ``~/seek`` services, Foxglove's time line)
moves the anchor under one lock and wakes the engine, which asks :meth:`PlayerState.decide`
before each message whether to publish it now, wait (how long), read the bag again from a
seek target, or stop. A message late because of a slow publish does not move the anchor, so
lateness does not accumulate.

Where playback ends follows rosbag2's player: ``--playback-until`` (a bag time) and
``--playback-duration`` (bag seconds from where playback starts) give an end time; with
both, the later one counts. Topic selection (``--topics``, ``--regex``, ``--exclude-topics``,
``--exclude-regex``) is :func:`select_topics`.
"""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from decimal import Decimal
from enum import Enum

from ssi_bridge.exceptions import RecordingError

NS = 1_000_000_000


class Action(Enum):
    """What the engine does with the next message (:meth:`PlayerState.decide`)."""

    PUBLISH = "publish"
    WAIT = "wait"
    RESEEK = "reseek"
    STOP = "stop"


@dataclass(frozen=True)
class Snapshot:
    """The player's state at one moment (progress line, Foxglove's PlaybackState)."""

    bag_ns: int
    rate: float
    paused: bool
    #: messages published since the start (all passes)
    published: int
    #: the bag's first and last log times
    first_ns: int
    end_ns: int
    ended: bool


def select_topics(available: Iterable[str], topics: list[str] | None = None,
                  regex: str = "", exclude_topics: list[str] | None = None,
                  exclude_regex: str = "") -> list[str]:
    """The topics to play, as rosbag2's player selects them.

    Included: every topic named in ``topics`` or matched by ``regex`` (``re.search``), or all
    when neither is given; then those named in ``exclude_topics`` or matched by
    ``exclude_regex`` are dropped. Raises RecordingError for a topic in ``topics`` that the bag
    does not have, a malformed expression, or a selection that leaves nothing to play. A topic
    in ``exclude_topics`` that the bag does not have excludes nothing and is no error, as for
    ``ros2 bag play`` (its storage filter only tests whether a recorded topic is in the list).

    :param available: the bag's topics
    :param topics: only these (``--topics``; None: all)
    :param regex: only topics matching it (``--regex``)
    :param exclude_topics: not these (``--exclude-topics``)
    :param exclude_regex: not topics matching it (``--exclude-regex``)
    """
    have = sorted(available)
    unknown = [t for t in topics or [] if t not in have]
    if unknown:
        raise RecordingError(f"no topic {', '.join(unknown)} in the bag "
                             f"(it has {', '.join(have)})")
    try:
        include = re.compile(regex) if regex else None
        exclude = re.compile(exclude_regex) if exclude_regex else None
    except re.error as err:
        raise RecordingError(f"regular expression {err.pattern!r}: {err}") from err
    if topics or include is not None:
        chosen = [t for t in have if t in (topics or []) or (include and include.search(t))]
    else:
        chosen = list(have)
    chosen = [t for t in chosen if t not in (exclude_topics or [])
              and not (exclude is not None and exclude.search(t))]
    if not chosen:
        raise RecordingError(f"the topic selection leaves nothing to play (the bag has "
                             f"{', '.join(have)})")
    return chosen


def until_time(start_ns: int, bag_start_ns: int, until: float | Decimal | str | None = None,
               duration: float | None = None, ros_time: bool = False) -> int | None:
    """The bag time after which playback stops (None: the end of the bag).

    ``until`` in seconds: a value at or after the bag's start (``bag_start_ns``) is a ROS time
    (``sec.nsec`` since the epoch), a smaller one seconds from the start of the bag;
    ``duration`` is bag seconds from ``start_ns`` (where playback starts). With both, the
    later time counts (rosbag2's rule). ``ros_time`` makes ``until`` a ROS time whatever its
    value (rosbag2's ``--playback-until-sec``/``-nsec``). ``until`` is read as a decimal (``str(float)`` for a
    float), so ``sec.nsec`` keeps its nanoseconds. Raises ValueError for a negative or
    malformed value.
    """
    ends = []
    if until is not None:
        try:
            exact = Decimal(str(until))
        except ArithmeticError as err:
            raise ValueError(f"playback until {until!r}: not a number") from err
        if not exact >= 0:
            raise ValueError(f"playback until {until}: must be >= 0")
        until_ns = int(exact * NS)
        ends.append(until_ns if ros_time or until_ns >= bag_start_ns
                    else bag_start_ns + until_ns)
    if duration is not None:
        if duration < 0:
            raise ValueError(f"playback duration {duration}: must be >= 0")
        ends.append(start_ns + round(duration * NS))
    return max(ends) if ends else None


class PlayerState:
    """The time line of one replay; every method is thread-safe.

    ``first_ns``..``end_ns`` is the bag's span (a seek is clamped into it), ``start_ns`` where
    playback starts (the bag start plus ``--start-offset``), ``until_ns`` where it stops.
    ``clock`` is the monotonic clock (a test passes its own).

    :param rate: the playback rate (1.0 = recorded speed)
    :param paused: start paused
    :param clock: the monotonic clock the time line runs on
    """

    def __init__(self, first_ns: int, end_ns: int, *, start_ns: int | None = None,
                 rate: float = 1.0, paused: bool = False, until_ns: int | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        _check_rate(rate)
        self.first_ns, self.end_ns = first_ns, end_ns
        self.start_ns = first_ns if start_ns is None else start_ns
        self.until_ns = until_ns
        self._clock = clock
        self._cond = threading.Condition()
        self._rate = rate
        self._paused = paused
        self._anchor_bag = self.start_ns
        self._anchor_wall = clock()
        self._steps = 0
        self._generation = 0
        self._seek_ns = self.start_ns
        self._stopped = False
        self._ended = False
        self._published = 0
        self._listeners: list[Callable[[str], None]] = []

    # -- observers -------------------------------------------------------------------------

    def on_change(self, listener: Callable[[str], None]) -> None:
        """Call ``listener(what)`` after each change ("pause", "resume", "rate", "seek",
        "step", "ended"), outside the lock."""
        self._listeners.append(listener)

    def _notify(self, what: str) -> None:
        for listener in list(self._listeners):
            listener(what)

    def _bag_now(self, now: float) -> int:
        if self._paused or self._ended:
            return self._anchor_bag
        return self._anchor_bag + int((now - self._anchor_wall) * self._rate * NS)

    def snapshot(self) -> Snapshot:
        """Where the time line is now."""
        with self._cond:
            now = self._clock()
            bag = min(max(self._bag_now(now), self.first_ns), self.end_ns)
            return Snapshot(bag, self._rate, self._paused, self._published, self.first_ns,
                            self.end_ns, self._ended)

    @property
    def generation(self) -> int:
        """Counts the seeks; the engine reads the bag again when it changes."""
        with self._cond:
            return self._generation

    @property
    def seek_ns(self) -> int:
        """Where the engine reads the bag from (the start, or the last seek's target)."""
        with self._cond:
            return self._seek_ns

    # -- controls --------------------------------------------------------------------------

    def pause(self) -> bool:
        """Stop the time line where it is; False when already paused."""
        with self._cond:
            if self._paused:
                return False
            self._anchor_bag = self._bag_now(self._clock())
            self._paused = True
            self._cond.notify_all()
        self._notify("pause")
        return True

    def resume(self) -> bool:
        """Run the time line again from where it stands; False when it was not paused."""
        with self._cond:
            if not self._paused:
                return False
            self._anchor_wall = self._clock()
            self._paused = False
            self._cond.notify_all()
        self._notify("resume")
        return True

    def toggle(self) -> bool:
        """Pause when playing, resume when paused; returns True when now paused."""
        if not self.pause():
            self.resume()
            return False
        return True

    @property
    def paused(self) -> bool:
        """Whether playback is paused."""
        with self._cond:
            return self._paused

    @property
    def rate(self) -> float:
        """The playback rate (1.0 = recorded speed)."""
        with self._cond:
            return self._rate

    def set_rate(self, rate: float) -> None:
        """Play at ``rate`` from now on (the bag time reached so far is kept).

        Raises ValueError unless ``rate`` > 0.
        """
        _check_rate(rate)
        with self._cond:
            now = self._clock()
            self._anchor_bag, self._anchor_wall = self._bag_now(now), now
            self._rate = float(rate)
            self._cond.notify_all()
        self._notify("rate")

    def step(self) -> bool:
        """Publish the next message at once while paused (rosbag2's play_next).

        False when not paused: a step only makes sense on a stopped time line.
        """
        with self._cond:
            if not self._paused or self._ended:
                return False
            self._steps += 1
            self._cond.notify_all()
        return True

    def seek(self, bag_ns: int) -> int:
        """Move the time line to ``bag_ns`` (clamped into the bag); returns the target.

        The engine reads the bag again from there: the next message published is the first
        one logged at or after the target. A paused player stays paused; a player that had
        reached the end plays again.
        """
        with self._cond:
            target = min(max(int(bag_ns), self.first_ns), self.end_ns)
            self._anchor_bag, self._anchor_wall = target, self._clock()
            self._seek_ns = target
            self._generation += 1
            self._steps = 0
            self._ended = False
            self._cond.notify_all()
        self._notify("seek")
        return target

    def stop(self) -> None:
        """End playback (shutdown): the engine's next decision is STOP."""
        with self._cond:
            self._stopped = True
            self._cond.notify_all()

    @property
    def stopped(self) -> bool:
        """Whether playback was stopped (:meth:`stop`): nothing more is played."""
        with self._cond:
            return self._stopped

    # -- the engine's side -----------------------------------------------------------------

    def restart(self, bag_ns: int | None = None) -> None:
        """Anchor the time line at ``bag_ns`` (default: the start) now: a new pass begins."""
        with self._cond:
            self._anchor_bag = self.start_ns if bag_ns is None else bag_ns
            self._anchor_wall = self._clock()
            self._ended = False

    def decide(self, log_time: int, generation: int) -> tuple[Action, float | None]:
        """What to do with the message logged at ``log_time``, read in pass ``generation``.

        Returns (PUBLISH, lateness s) when it is due, (PUBLISH, None) for a step pending while
        paused (the time line moves to the message), (WAIT, seconds or None while paused) when it is not,
        (RESEEK, None) after a seek, (STOP, None) past the end time or after :meth:`stop`.
        """
        with self._cond:
            if self._stopped:
                return Action.STOP, None
            if generation != self._generation:
                return Action.RESEEK, None
            if self.until_ns is not None and log_time > self.until_ns:
                return Action.STOP, None
            now = self._clock()
            if self._paused:
                if self._steps > 0:
                    self._steps -= 1
                    self._anchor_bag, self._anchor_wall = log_time, now
                    return Action.PUBLISH, None
                return Action.WAIT, None
            due = self._anchor_wall + (log_time - self._anchor_bag) / NS / self._rate
            if now >= due:
                return Action.PUBLISH, now - due
            return Action.WAIT, due - now

    def played(self) -> None:
        """Count one published message."""
        with self._cond:
            self._published += 1

    def wait(self, timeout: float | None) -> None:
        """Sleep until ``timeout`` passes or a control changes the time line."""
        with self._cond:
            self._cond.wait(timeout)

    def finish(self) -> None:
        """The pass reached its end: the time line stops at the last time played."""
        with self._cond:
            self._anchor_bag = min(self._bag_now(self._clock()), self.until_ns or self.end_ns,
                                   self.end_ns)
            self._ended = True
        self._notify("ended")

    def wait_for_seek(self, generation: int, timeout: float | None) -> bool:
        """After the end: wait until a seek (True) or :meth:`stop` / ``timeout`` (False).

        :param generation: the time line's generation seen at the end (a seek makes a new one)
        :param timeout: longest wait (s; None: no limit)
        """
        with self._cond:
            self._cond.wait_for(lambda: self._stopped or self._generation != generation,
                                timeout)
            return not self._stopped and self._generation != generation


def _check_rate(rate: float) -> None:
    if not rate > 0 or rate == float("inf"):
        raise ValueError(f"rate {rate}: must be > 0")


__all__ = ["Action", "PlayerState", "Snapshot", "select_topics", "until_time"]
