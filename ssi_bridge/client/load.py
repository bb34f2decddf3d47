"""Bus load as the master sees it: wire time of every frame on the bus, from frame timestamps.

Each frame handled (received, with its receive timestamp, or sent by this master) adds its
length at the bit rate (``gateway/wire.frame_bits``: SOF to IFS with its actual stuff bits).
Over the last ``window`` seconds of frame timestamps the figures are the load (wire time /
window), frames and wire time per SYNC cycle: what ``ssi_bridge: bus`` shows.
"""

from __future__ import annotations

import threading
from collections import deque

import can

from ssi_bridge.base.timebase import wire_now
from ssi_bridge.protocol.wire import frame_bits

SYNC_COB_ID = 0x080


class BusLoad:
    """Frames (timestamp, and the bits and SYNCs counted before it) of the last ``window``
    seconds, and the running totals: :meth:`figures` takes a window's wire time and SYNCs as
    the difference of two running totals, whatever the window holds.

    The receive and cycle threads add, the diagnostics read, under one lock held for a few
    operations (no sum over the window while other threads wait for the GIL: the figures of
    a second of frames at 1 kHz took ~1 ms of interpreter time, on the diagnostics' timer,
    while the receive thread waited). Adding a frame also drops the frames a window older
    than it, so the window holds what :meth:`figures` reads and no more.

    :param bitrate: the bus's bit rate (bit/s)
    :param window: seconds of frames the load is computed over
    """

    def __init__(self, bitrate: int, window: float = 1.0) -> None:
        self.bitrate = bitrate
        self.window = window
        #: (wire time, bits added before this frame, SYNCs added before this frame)
        self._frames: deque[tuple[float, int, int]] = deque()
        #: bits and SYNCs of every frame added so far
        self._bits = 0
        self._syncs = 0
        self._lock = threading.Lock()

    def add(self, msg: can.Message) -> None:
        """Account one frame (its timestamp, or now when it has none).

        :param msg: the frame as python-can received or sent it
        """
        if msg.is_error_frame or msg.is_extended_id or msg.is_fd:
            return
        can_id = msg.arbitration_id
        bits = frame_bits(can_id, msg.data, msg.is_remote_frame, msg.dlc)
        # its wire time (base/timebase.frame_wire_time, inline: every frame passes here)
        t = getattr(msg, "wire_time", 0.0) or msg.timestamp or wire_now()
        with self._lock:
            frames = self._frames
            frames.append((t, self._bits, self._syncs))
            self._bits += bits
            if can_id == SYNC_COB_ID:
                self._syncs += 1
            oldest = t - self.window
            while frames[0][0] < oldest:  # never the frame just added
                frames.popleft()

    def figures(self, now: float | None = None) -> dict[str, str]:
        """load %, frames and wire time per cycle over the window ending ``now``.

        The window is on the frames' wire times (their stamps: what the bus carried when).
        A frame more than a window after ``now`` was stamped before the wall clock stepped
        back: dropped like an old one, or the window would keep every frame since the step
        (memory grows for as long as the step was).
        """
        now = wire_now() if now is None else now
        with self._lock:
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


__all__ = ["BusLoad"]
