"""Bus load as the master sees it: wire time of every frame on the bus, from frame timestamps.

Each frame handled (received, with its receive timestamp, or sent by this master) adds its
length at the bit rate (``gateway/wire.frame_bits``: SOF to IFS with its actual stuff bits).
Over the last ``window`` seconds of frame timestamps the figures are the load (wire time /
window), frames and wire time per SYNC cycle: what ``ssi_bridge: bus`` shows.

A received frame is only queued on the receive thread (:attr:`BusLoad.received`, one append);
a frame the master sends is measured at once and queued behind it (:meth:`BusLoad.add`: the
sender may reuse its payload). The queue is counted, in the order the frames were handled, by
the cycle thread once its cycle is over (:meth:`BusLoad.count_queued`, with time to spare) and
by :meth:`BusLoad.figures`, whichever comes first: the figures are those of counting each
frame as it came.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable

import can

from ssi_bridge.base.timebase import wire_now
from ssi_bridge.protocol.wire import frame_bits

logger = logging.getLogger(__name__)

SYNC_COB_ID = 0x080


#: a frame of the queue: a received one, or a sent one measured already (wire time, bits,
#: is SYNC)
_Queued = can.Message | tuple[float, int, bool]
#: queued frames beyond which a sent frame counts them: a master whose cycle does not count
#: them (a loop of its own, a tool) holds a few cycles' frames, not thousands of live frame
#: objects for the garbage collector to walk
QUEUE_LIMIT = 64


#: bits of the SYNC without a counter (CiA 301), every cycle's same frame: counted once
_SYNC_BITS = frame_bits(SYNC_COB_ID)


def _measure(msg: can.Message) -> tuple[float, int, bool] | None:
    """A frame's (wire time, bits on the wire, is SYNC); None for a frame the load leaves out
    (an error, extended or FD frame). Its wire time is its stamp (base/timebase.frame_wire_time,
    inline), or now when it has none.

    :raises ValueError: no classic CAN frame has it (protocol/wire.frame_bits)
    """
    if msg.is_error_frame or msg.is_extended_id or msg.is_fd:
        return None
    can_id, dlc, remote = msg.arbitration_id, msg.dlc, msg.is_remote_frame
    sync = can_id == SYNC_COB_ID
    bits = (_SYNC_BITS if sync and dlc == 0 and not remote
            else frame_bits(can_id, msg.data, remote, dlc))
    return getattr(msg, "wire_time", 0.0) or msg.timestamp or wire_now(), bits, sync


class BusLoad:
    """Frames (timestamp, and the bits and SYNCs counted before it) of the last ``window``
    seconds, and the running totals: :meth:`figures` takes a window's wire time and SYNCs as
    the difference of two totals (no sum over a second of frames while the receive thread
    waits for the GIL), and counting a frame drops the frames a window older than it.

    The receive thread queues (:attr:`received`), any sending thread adds (:meth:`add`), the
    cycle thread (:meth:`count_queued`) and the diagnostics (:meth:`figures`) count: a deque's
    appends and pops are thread-safe, the queued frames are counted by one thread at a time
    under the read lock (a thread that finds another counting leaves them to it), and only
    :meth:`figures` pops the oldest counted frames.

    :param bitrate: the bus's bit rate (bit/s)
    :param window: seconds of frames the load is computed over
    """

    def __init__(self, bitrate: int, window: float = 1.0) -> None:
        self.bitrate = bitrate
        self.window = window
        #: (wire time, bits counted before this frame, SYNCs counted before this frame)
        self._frames: deque[tuple[float, int, int]] = deque()
        #: bits and SYNCs of every frame counted so far
        self._bits = 0
        self._syncs = 0
        #: frames not counted yet, in the order they were handled
        self._queued: deque[_Queued] = deque()
        #: queue one received frame (the receive thread, every frame: one C call, no lock);
        #: its timestamp and content are read when it is counted, so the frame must not change
        self.received: Callable[[can.Message], None] = self._queued.append
        self._read_lock = threading.Lock()
        #: received frames left out of the figures: not a classic CAN frame (logged once)
        self.not_counted = 0

    def add(self, msg: can.Message) -> None:
        """Account one frame (a frame this master sent: its timestamp, or now when it has
        none), measured now and counted after the frames queued before it.

        :param msg: the frame as python-can sent (or received) it
        """
        measured = _measure(msg)
        if measured is not None:
            self._queued.append(measured)
            if len(self._queued) > QUEUE_LIMIT:
                self.count_queued()

    def count_queued(self) -> None:
        """Count the queued frames now (a thread with time to spare: the cycle thread once
        its cycle is over), unless another thread is counting them."""
        if self._queued and self._read_lock.acquire(blocking=False):
            try:
                self._count_queued()
            finally:
                self._read_lock.release()

    def _count_queued(self) -> None:
        """Under the read lock: count every queued frame, oldest first (a received frame as
        :meth:`add` measures one; one without a timestamp takes now's), and drop the frames a
        window older than the last one counted."""
        queued, frames = self._queued, self._frames
        take, keep = queued.popleft, frames.append
        bits, syncs = self._bits, self._syncs
        t = None
        try:
            while queued:
                msg = take()
                if isinstance(msg, tuple):  # sent: measured already
                    t, size, sync = msg
                else:
                    try:
                        measured = _measure(msg)
                    except ValueError as err:  # no classic frame (an id above 0x7FF)
                        self._not_counted(msg, err)
                        continue
                    if measured is None:
                        continue
                    t, size, sync = measured
                keep((t, bits, syncs))
                bits += size
                syncs += sync
        finally:  # the totals of what was kept, whatever ended the loop
            self._bits, self._syncs = bits, syncs
        if t is not None:
            oldest = t - self.window
            while frames[0][0] < oldest:  # never the frame counted last
                frames.popleft()

    def _not_counted(self, msg: can.Message, err: ValueError) -> None:
        """A received frame no classic CAN frame can be (an interface that passes an 11-bit
        id above 0x7FF): counted in :attr:`not_counted`, said once."""
        self.not_counted += 1
        if self.not_counted == 1:
            logger.warning("bus load: a received frame is not a classic CAN frame and is not "
                           "counted (%s: id 0x%X); later ones are counted in not_counted only",
                           err, msg.arbitration_id)

    def figures(self, now: float | None = None) -> dict[str, str]:
        """load %, frames and wire time per cycle over the window ending ``now``.

        The window is on the frames' wire times (their stamps: what the bus carried when).
        A frame more than a window after ``now`` was stamped before the wall clock stepped
        back: dropped like an old one, or the window would keep every frame since the step
        (memory grows for as long as the step was).
        """
        now = wire_now() if now is None else now
        with self._read_lock:
            self._count_queued()
            frames = self._frames
            while frames and not now - self.window <= frames[0][0] <= now + self.window:
                frames.popleft()
            count = len(frames)
            bits = self._bits - frames[0][1] if frames else 0
            syncs = self._syncs - frames[0][2] if frames else 0
        busy = bits / self.bitrate
        return {
            "bus_load_percent": f"{100.0 * busy / self.window:.1f}",
            "frames_per_cycle": f"{count / syncs:.2f}" if syncs else "0",
            "wire_ms_per_cycle": f"{1e3 * busy / syncs:.3f}" if syncs else "0",
            "bus_bitrate": str(self.bitrate),
        }


__all__ = ["QUEUE_LIMIT", "BusLoad"]
