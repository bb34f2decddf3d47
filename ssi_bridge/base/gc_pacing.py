"""Python's cyclic garbage collector, run by the cycle thread in its spare time.

CPython collects when a thread allocates its 700th tracked object since the last collection,
on whichever thread that is. In the node that is mostly the receive thread (it allocates a
frame object per TPDO), so a young-generation collection (a few hundred µs on a busy 2-core
machine) lands between a cycle's last TPDO and its ``publish()``, a few times a second: the
driver's p99 span. :class:`CollectorPacing` turns the automatic collector off while a cycle
thread runs and collects instead when that thread has time to spare after a cycle (the same
generations, by CPython's own counters and thresholds), so no collection runs on the receive
thread. Objects are freed by reference counting as before; only reference cycles wait for the
cycle thread, at most :data:`FORCE_FACTOR` times the threshold's allocations even without
spare time. What the process holds when the first cycle thread starts (its modules, the node,
its configuration) is moved out of the collector's view (``gc.freeze``), so an old-generation
collection scans only what was kept since, not the whole heap. Automatic collection comes back
(and the frozen objects into view) when the last cycle thread stops.

Several cycle threads in one process (tests, several nodes) share one pacing: the collector
stays off while any of them runs.
"""

from __future__ import annotations

import gc
import threading

#: collect even without spare time once this many times the threshold's allocations wait
FORCE_FACTOR = 2


class CollectorPacing:
    """The garbage collector paced by a cycle thread (see the module docstring).

    ``start()`` when the thread starts, ``step(spare)`` after each of its cycles, ``stop()``
    when it ends (also when it fails: the collector must not stay off).
    """

    _lock = threading.Lock()
    _running = 0
    _was_enabled = True

    def __init__(self) -> None:
        #: collections this pacing ran, per generation
        self.collections = [0, 0, 0]

    def start(self) -> None:
        """Turn automatic collection off and freeze what exists (the first running pacing in
        the process)."""
        cls = CollectorPacing
        with cls._lock:
            if cls._running == 0:
                cls._was_enabled = gc.isenabled()
                gc.disable()
                gc.freeze()
            cls._running += 1

    def stop(self) -> None:
        """Give collection back to CPython when no pacing runs any more (idempotent per
        ``start``: a stop without a start does nothing)."""
        cls = CollectorPacing
        with cls._lock:
            if cls._running == 0:
                return
            cls._running -= 1
            if cls._running == 0:
                gc.unfreeze()
                if cls._was_enabled:
                    gc.enable()

    def step(self, spare: bool) -> int:
        """Collect the generation CPython would have collected by now, if any is due and
        ``spare`` (the cycle thread has time before its next SYNC) or the backlog is
        :data:`FORCE_FACTOR` times the young threshold.

        :returns: the generation collected, -1 for none
        """
        young, middle, old = gc.get_count()
        limit0, limit1, limit2 = gc.get_threshold()
        if limit0 <= 0 or young < limit0 or not (spare or young >= FORCE_FACTOR * limit0):
            return -1
        generation = 2 if old >= limit2 > 0 and middle >= limit1 else \
            1 if middle >= limit1 else 0
        gc.collect(generation)
        self.collections[generation] += 1
        return generation


__all__ = ["CollectorPacing", "FORCE_FACTOR"]
