"""Logging that cannot flood: at most one line per second per kind of event.

A hostile or broken bus can produce thousands of identical faults a second (undecodable
datagrams, receive errors, heartbeats in no CiA 301 state). Each one is counted by its owner;
the log says it at most once per :data:`LOG_INTERVAL` per kind, with how many of that kind
were not logged since the last line, so the log stays readable and the counters tell the rest.
"""

from __future__ import annotations

import logging
import threading
import time

#: at most one log line per kind within this many seconds
LOG_INTERVAL = 1.0


class RateLimitedLog:
    """One logger, at most one line per ``interval`` per kind (thread-safe).

    :param logger: where the lines go
    :param interval: seconds between two lines of one kind
    """

    def __init__(self, logger: logging.Logger, interval: float = LOG_INTERVAL) -> None:
        self._logger = logger
        self._interval = interval
        self._lock = threading.Lock()
        #: kind -> (monotonic time of its last line, events not logged since)
        self._kinds: dict[str, tuple[float, int]] = {}

    def log(self, level: int, kind: str, msg: str, *args: object,
            exc_info: BaseException | None = None) -> bool:
        """Log ``msg % args`` at ``level`` unless ``kind`` was logged within the interval.

        Returns True when the line was written. A line after suppressed events ends with
        "(N more since the last line)".

        :param exc_info: the exception whose traceback to add (None: none)
        """
        now = time.monotonic()
        with self._lock:
            last, skipped = self._kinds.get(kind, (-float("inf"), 0))
            if now - last < self._interval:
                self._kinds[kind] = (last, skipped + 1)
                return False
            self._kinds[kind] = (now, 0)
        if skipped:
            msg = f"{msg} ({skipped} more since the last line)"
        self._logger.log(level, msg, *args, exc_info=exc_info)
        return True

    def warning(self, kind: str, msg: str, *args: object) -> bool:
        """:meth:`log` at WARNING.

        :param kind: the kind of event (rate-limited per kind)
        :param msg: the %-format of the line
        :param args: its arguments
        :returns: True when the line was written
        """
        return self.log(logging.WARNING, kind, msg, *args)

    def error(self, kind: str, msg: str, *args: object,
              exc_info: BaseException | None = None) -> bool:
        """:meth:`log` at ERROR (``exc_info``: the exception whose traceback to add).

        :param kind: the kind of event (rate-limited per kind)
        :param msg: the %-format of the line
        :param args: its arguments
        :returns: True when the line was written
        """
        return self.log(logging.ERROR, kind, msg, *args, exc_info=exc_info)


__all__ = ["LOG_INTERVAL", "RateLimitedLog"]
