"""CanLogPlayer: send a recorded CAN log onto a virtual bus with its original timing.

A session recorded with ``record.can_log`` holds the raw traffic beside the bag
(``client/sniffer.py``, candump format). Played back onto a private python-can ``virtual``
channel, a :class:`~ssi_bridge.client.listener.ListenOnlyClient` on that channel sees the
station exactly as the recording master did.

Timing: frame k is sent at ``start + (t_k - t_0) / rate`` (own loop on ``time.monotonic()``
rather than ``can.MessageSync``, so :meth:`stop` ends a long gap at once). Each frame keeps
its original spacing in its timestamp: ``t_k - t_0`` after the ``time.time()`` of the start,
i.e. the logged times shifted to the start of the replay, whatever ``rate`` is; the bus is
opened with ``preserve_timestamps`` so receivers see that stamp, not the send time.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path

import can

from ssi_bridge.exceptions import BusError, ConfigError

logger = logging.getLogger(__name__)


class CanLogPlayer:
    """Play ``path`` onto virtual channel ``channel`` once, in a thread.

    :param path: a python-can log (``.log`` candump, ``.asc``, ``.blf``, ...)
    :param channel: python-can ``virtual`` channel to send on
    :param rate: speed factor (2.0 = twice as fast); timestamps keep the original spacing
    :param on_end: called (from the player thread) after the last frame, or on a read error

    :raises ConfigError: the log is not a file, or ``rate`` is not positive
    :raises BusError: the virtual channel cannot be opened
    """

    def __init__(self, path: str | Path, channel: str, *, rate: float = 1.0,
                 on_end: Callable[[], None] | None = None) -> None:
        self.path = Path(path).expanduser()
        if not self.path.is_file():
            raise ConfigError(f"CAN log {self.path} does not exist or is not a file")
        if not rate > 0:
            raise ConfigError(f"replay rate {rate} must be > 0")
        self.channel = channel
        self.rate = rate
        self._on_end = on_end
        self._stop = threading.Event()
        #: set when the log has been played to its end (or could not be read further)
        self.finished = threading.Event()
        #: frames sent so far
        self.frames = 0
        #: why the replay ended early ("" when it reached the end of the log)
        self.error = ""
        try:
            self._bus = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
        except (can.CanError, OSError, ValueError) as err:
            raise BusError(f"cannot open virtual channel {channel!r} for replay: {err}") from err
        self._thread = threading.Thread(target=self._run, name="ssi_can_replay", daemon=True)

    def start(self) -> None:
        """Start playing (once)."""
        logger.info("replaying %s onto virtual:%s at %gx", self.path, self.channel, self.rate)
        self._thread.start()

    def start_when(self, heard: Callable[[], bool], timeout: float,
                   running: Callable[[], bool]) -> None:
        """Start once ``heard()`` (someone listens) or ``timeout`` passed, from a thread of
        its own; not at all if ``running()`` turned false meanwhile (the node stopped)."""
        def wait() -> None:
            deadline = time.monotonic() + timeout
            while not heard() and time.monotonic() < deadline and running():
                time.sleep(0.02)
            if running():
                self.start()
        threading.Thread(target=wait, name="replay-wait", daemon=True).start()

    def stop(self, timeout: float = 2.0) -> None:
        """Stop playing and close the bus; safe to call twice.

        :param timeout: how long to wait for the player thread (s)
        """
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        self._bus.shutdown()

    def _run(self) -> None:
        start_mono = time.monotonic()
        start_wall = time.time()
        first: float | None = None
        try:
            with can.LogReader(str(self.path)) as reader:
                for msg in reader:
                    if first is None:
                        first = msg.timestamp
                    offset = msg.timestamp - first
                    wait = start_mono + offset / self.rate - time.monotonic()
                    if (wait > 0 and self._stop.wait(wait)) or self._stop.is_set():
                        return
                    msg.timestamp = start_wall + offset
                    self._bus.send(msg)
                    self.frames += 1
        except (can.CanError, OSError, ValueError) as err:
            self.error = f"{type(err).__name__}: {err}"
            logger.error("replay of %s stopped after %d frames: %s", self.path, self.frames,
                         self.error)
        self.finished.set()
        logger.info("replay of %s ended: %d frames sent", self.path, self.frames)
        if self._on_end is not None:
            self._on_end()
