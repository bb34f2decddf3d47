"""The bridge's cycle clock: a dedicated thread that runs one bus cycle per period.

An rclpy timer would run each cycle through the executor (wait-set rebuild, callback-group
bookkeeping), which at 1 kHz costs as much CPU as the cycle itself. Like a ros2_control
hardware loop, the cycle gets its own thread on an absolute schedule; publishing from it is
thread-safe in rclpy, and the executor only serves services, parameters and diagnostics.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from ssi_bridge.base.gc_pacing import CollectorPacing
from ssi_bridge.base.realtime import run_this_thread_at
from ssi_bridge.protocol import wire

logger = logging.getLogger(__name__)

#: a cycle longer on the wire than its period waits at least this many times its worst-case
#: wire time for the TPDOs (the rest is the receive path: a datagram between processes, the
#: notifier thread)
WIRE_WAIT_FACTOR = 1.2
#: at most this long (s) for one cycle's TPDOs
MAX_WAIT_S = 0.05
#: a station that has answered nothing is given up to this long (s): starved, not lossy
STARVED_WAIT_S = 0.02


def cycle_waits(period: float, cycle_wire_s: float) -> tuple[float, float]:
    """How long (s) one cycle waits for its TPDOs: (in any case, while a station has not
    answered the SYNC at all).

    Up to 90 % of the period, the next SYNC going out at the period boundary. A cycle longer
    on the wire than the period waits its wire time instead: a frame is not lost before its
    end on the wire, and a SYNC sent while the cycle's TPDOs are still on it would only delay
    them, so a publish_rate that does not fit runs complete cycles at the rate that does
    (the cycle thread skips to the next slot), while one that fits keeps its period. A station
    that has answered nothing is starved of CPU rather than lossy and gets its turn, up to
    :data:`STARVED_WAIT_S`. Frames lost on the wire never come, so they do not hold up the next
    SYNC.
    """
    first = min(0.9 * period, MAX_WAIT_S)
    if cycle_wire_s > period:
        first = max(first, WIRE_WAIT_FACTOR * cycle_wire_s)
    return first, max(min(max(0.9 * period, STARVED_WAIT_S), MAX_WAIT_S), first)


def cycle_wire_time(s: Any, warn: Callable[[str], None]) -> float:
    """The worst-case wire time (s) of one cycle of the settings ``s`` (a ``NodeSettings``);
    ``warn`` says so when publish_rate's cycles do not fit the wire at bus.bitrate
    (protocol/wire.py). Several stations share the bus's budget: one SYNC, every TPDO."""
    counts = [max(j.slot for j in s.station_joints(sid)) for sid in s.station_ids]
    seconds = wire.frame_seconds(wire.stations_cycle_bits(counts), s.bus_bitrate)
    if s.listen_only or wire.stations_fits(counts, s.bus_bitrate, s.publish_rate):
        return seconds
    what = (f"{counts[0]} slot(s)" if len(counts) == 1 else
            f"{len(counts)} stations with {'+'.join(map(str, counts))} slots")
    warn(f"publish_rate {s.publish_rate:g} Hz does not fit the CAN wire: one cycle of "
         f"{what} (SYNC + TPDOs) takes up to {seconds * 1e3:.3f} ms at "
         f"{s.bus_bitrate} bit/s, plus {wire.SDO_RESERVE_FRAMES} frames reserved for register "
         f"traffic; the highest rate that fits is "
         f"{wire.stations_max_cycle_rate(counts, s.bus_bitrate):g} Hz (docs/canopen.md)")
    return seconds


class LoopThread:
    """A daemon thread running ``_run`` until :meth:`stop`; the loops of the node share it.

    :param name: the thread's name, also its kernel name (``top -H`` shows it)
    :param priority: SCHED_FIFO priority the thread asks for (0: normal scheduling); whether
        it got it is :attr:`scheduling`, and a refusal is logged once at INFO
    """

    def __init__(self, name: str, priority: int = 0) -> None:
        self._stop = threading.Event()
        #: held while the thread sleeps; :meth:`stop` releases it to end a sleep at once (one
        #: lock acquire a sleep: an Event's wait costs a condition and a new lock each time)
        self._wake = threading.Lock()
        self._wake.acquire()
        self._thread = threading.Thread(target=self._main, name=name, daemon=True)
        self.priority = priority
        #: the thread's scheduling once it runs ("SCHED_FIFO 5", "normal"; "" before)
        self.scheduling = ""

    def start(self) -> None:
        """Start the thread (once)."""
        self._thread.start()

    def stop(self, timeout: float = 2.0) -> None:
        """Ask the thread to end and wait for the running step to finish."""
        self._stop.set()
        if self._wake.locked():
            try:
                self._wake.release()
            except RuntimeError:  # released meanwhile by another stop()
                pass
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout)

    def _main(self) -> None:
        self.scheduling, granted = run_this_thread_at(self._thread.name, self.priority)
        if not granted:
            logger.info("%s thread runs with normal scheduling: SCHED_FIFO %d not permitted "
                        "(needs CAP_SYS_NICE or an rtprio limit; cycle_priority 0 skips this)",
                        self._thread.name, self.priority)
        self._run()

    def _run(self) -> None:
        raise NotImplementedError

    def _sleep(self, seconds: float) -> None:
        """Sleep ``seconds`` (a stop ends the sleep at once)."""
        if seconds > 0 and self._wake.acquire(timeout=seconds):
            self._wake.release()  # stopped: every later sleep ends at once too


#: a cycle leaves time to spare for a garbage collection when at least this share of the
#: period is left before the next step
GC_SPARE = 0.5


class CycleThread(LoopThread):
    """Call ``step()`` every ``period`` seconds on an absolute schedule until stopped.

    A step that ends less than half a period late runs the next cycle at once; one that
    overruns further skips to the next slot boundary (the skipped slots are counted in
    ``missed``) instead of bursting to catch up: a burst of SYNCs helps no master. ``end``,
    if given, runs once on the thread after its last step (what a step left to the next one).
    While it runs, Python's garbage collector runs on it between steps with time to spare
    (:attr:`pacing`), not wherever an allocation happens to trigger it.
    """

    def __init__(self, period: float, step: Callable[[], None], name: str = "ssi_cycle",
                 clock: Callable[[], float] = time.monotonic, priority: int = 0,
                 end: Callable[[], None] | None = None) -> None:
        if not period > 0:
            raise ValueError(f"cycle period {period} s must be > 0")
        super().__init__(name, priority)
        self.period = period
        self._step = step
        self._end = end
        self._clock = clock
        #: cycles run and cycles skipped because a step overran its slot
        self.cycles = 0
        self.missed = 0
        #: Python's garbage collector, run here when a cycle leaves time to spare
        #: (base/gc_pacing.py): never on the receive thread between a TPDO and publish()
        self.pacing = CollectorPacing()

    def _run(self) -> None:
        self.pacing.start()
        try:
            self._loop()
        finally:
            self.pacing.stop()

    def _loop(self) -> None:
        deadline = self._clock()
        while not self._stop.is_set():
            try:
                self._step()
            except Exception:  # noqa: BLE001 - the loop must outlive one bad cycle
                logger.exception("cycle step failed; continuing with the next cycle")
            self.cycles += 1
            deadline += self.period
            now = self._clock()
            if self.pacing.step(deadline - now >= GC_SPARE * self.period) >= 0:
                now = self._clock()  # the collection took its time
            if now >= deadline:
                late = now - deadline
                if late < 0.5 * self.period:
                    continue  # a little late: run this slot at once
                behind = int(late / self.period) + 1  # skip to the next slot boundary
                self.missed += behind
                deadline += behind * self.period
            self._sleep(deadline - now)
        if self._end is not None:
            try:
                self._end()
            except Exception:  # noqa: BLE001 - a thread never dies with an unlogged error
                logger.exception("the cycle's end failed")
