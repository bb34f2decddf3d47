"""The cycle's gate: one wake-up per cycle for the stations of one master, and the hand-off
of a complete cycle to the thread its last frame arrived on (the receive thread).
"""

from __future__ import annotations

import threading
from collections.abc import Callable


class CycleGate:
    """One condition and one wake-up per cycle for the slot tables of several stations, and
    the hand-off of a complete cycle to the thread its last frame arrived on.

    The master sets ``pending`` to the number of stations at each SYNC; a table whose cycle
    completes counts it down, and only the last one wakes the cycle's waiter, so the cycle
    thread is woken once per cycle however many stations answer.

    Hand-off: after sending its SYNC the cycle thread may :meth:`arm` the cycle with what to
    run for it. The frame that completes an armed cycle then takes it (:meth:`take`, under
    :attr:`cond`) and its thread, the receive thread, runs it (:meth:`run`) at once, out of
    the lock, without waking the cycle thread first; the waiter is woken once that run has
    ended. The cycle thread, whose wait ends then or at its timeout, :meth:`claim`\\ s the
    cycle and runs it itself only when no frame took it (a cycle that never completed,
    decided at the timeout as before). Exactly one of the two runs each armed cycle, and
    :meth:`claim` returns only after the receive thread's run ended, so the next SYNC never
    overtakes a cycle still being published. A SYNC sent while nothing is armed (a register
    handshake's own between two cycles) is run by nobody; one sent during an armed cycle's
    wait (a handshake's, from another thread) leaves it armed: the frame completing the
    handshake's SYNC completes the armed cycle, as the cycle thread's wait ended there before.
    """

    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.pending = 0
        #: what the completing frame's thread runs (None: nothing armed)
        self._armed: Callable[[], None] | None = None
        self._running = False

    def open(self, stations: int) -> None:
        """A SYNC for ``stations`` tables is about to go out (call under :attr:`cond`)."""
        self.pending = stations

    def _done(self) -> bool:
        return self.pending <= 0 and not self._running

    def wait(self, timeout: float) -> bool:
        """Wait until every station's cycle is complete (and a hand-off's run has ended) or
        ``timeout`` (s) elapses."""
        with self.cond:
            return self.cond.wait_for(self._done, timeout)

    def arm(self, run: Callable[[], None]) -> bool:
        """Hand the current cycle to the frame that completes it, which calls ``run`` on its
        thread; False when the cycle is complete already: the caller runs it itself."""
        with self.cond:
            if self.pending <= 0:
                return False
            self._armed = run
            return True

    def take(self) -> Callable[[], None] | None:
        """Under :attr:`cond`, by the frame that completed the cycle: what to :meth:`run` once
        the caller released :attr:`cond` (None: nothing armed; wake the waiters now)."""
        run = self._armed
        if run is not None:
            self._armed = None
            self._running = True
        return run

    def run(self, job: Callable[[], None]) -> None:
        """Run ``job`` (what :meth:`take` gave), then wake the cycle's waiter: its wait and
        :meth:`claim` end."""
        try:
            job()
        finally:
            with self.cond:
                self._running = False
                self.cond.notify_all()

    def claim(self) -> bool:
        """The cycle thread, after its wait: True when it runs the armed cycle itself (no
        frame took it); False when the receive thread took it, once that run has ended."""
        with self.cond:
            if self._armed is not None:
                self._armed = None
                return True
            self.cond.wait_for(lambda: not self._running)
            return False


__all__ = ["CycleGate"]
