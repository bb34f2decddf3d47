"""The listen-only node's cycle: one published cycle per SYNC another master (or a log) sent.

In listen-only mode (``bus.listen_only`` or ``replay.can_log``) the node must not produce
SYNC, so :class:`~ssi_bridge.ros.cycle.CycleThread` is replaced by this thread: it takes each
cycle the :class:`~ssi_bridge.client.listener.ListenOnlyClient` observed and hands it to the
node. Each ``period`` without a SYNC counts as a quiet cycle (the joints go STALE after
``stale_cycles`` of them, as when the real cycle got no TPDO). When a replayed log has ended
and the bus is quiet, ``on_end`` runs once. A live bus without any SYNC for
:data:`SILENT_WARNING_S` gets one warning (the other master may not run), and one line when
SYNCs come back.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from ssi_bridge.client.listener import ListenOnlyClient, ObservedCycle
from ssi_bridge.ros.cycle import LoopThread

logger = logging.getLogger(__name__)

#: seconds without any SYNC after which a listen-only node warns that the bus is silent
SILENT_WARNING_S = 5.0


class ObservedCycleThread(LoopThread):
    """Call ``step(cycle)`` per observed SYNC, ``quiet()`` per silent period, until stopped.

    :param client: the listener whose cycles are taken
    :param period: seconds without a SYNC that count as one quiet cycle (1 / publish_rate);
        may be changed at run time
    :param step: called with each observed cycle, in order
    :param quiet: called once per silent ``period``
    :param ended: set when the traffic source has no more frames (a log replay), or None
    :param on_end: called once after ``ended`` is set and the last cycle was handled
    :param silent_warning: seconds without SYNC before the silent-bus warning; None: never
        (a log replay says when it ends instead)
    :param priority: SCHED_FIFO priority of the thread (0: normal scheduling)
    """

    def __init__(self, client: ListenOnlyClient, period: float,
                 step: Callable[[ObservedCycle], None], quiet: Callable[[], None], *,
                 ended: threading.Event | None = None,
                 on_end: Callable[[], None] | None = None,
                 silent_warning: float | None = SILENT_WARNING_S, priority: int = 0) -> None:
        if not period > 0:
            raise ValueError(f"cycle period {period} s must be > 0")
        super().__init__("ssi_observe", priority)
        self.period = period
        self._client = client
        self._step = step
        self._quiet = quiet
        self._ended = ended
        self._on_end = on_end
        #: cycles handed to ``step`` and silent periods seen
        self.cycles = 0
        self.quiet_periods = 0
        self._silent_warning = silent_warning
        #: when the last SYNC (or the start) was seen, and whether the silence was reported
        self._heard = time.monotonic()
        self._warned = False

    def _run(self) -> None:
        end_reported = False
        while not self._stop.is_set():
            cycle = self._client.next_cycle(self.period)
            if self._stop.is_set():
                return
            try:
                if cycle is not None:
                    self.cycles += 1
                    self._heard_sync()
                    self._step(cycle)
                    continue
                self.quiet_periods += 1
                self._check_silence()
                self._quiet()
                if (not end_reported and self._ended is not None and self._ended.is_set()
                        and self._on_end is not None):
                    end_reported = True
                    self._on_end()
            except Exception:  # noqa: BLE001 - the loop must outlive one bad cycle
                logger.exception("observed cycle failed; continuing with the next one")

    def _heard_sync(self) -> None:
        now = time.monotonic()
        if self._warned:
            logger.info("listen-only: SYNC observed again after %.1f s of silence",
                        now - self._heard)
            self._warned = False
        self._heard = now

    def _check_silence(self) -> None:
        """Warn once when no SYNC was seen for ``silent_warning`` seconds."""
        if self._silent_warning is None or self._warned:
            return
        silent = time.monotonic() - self._heard
        if silent >= self._silent_warning:
            self._warned = True
            logger.warning(
                "listen-only: no SYNC on the bus for %.0f s; nothing is published until another "
                "master sends SYNC (is it running, on this bus and bit rate?)", silent)
