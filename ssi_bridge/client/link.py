"""The master's CAN interface across its loss: closed on an OS error, reopened with back-off.

A socketcan interface taken down (``ip link set can0 down``: ENETDOWN), a USB adapter pulled
out (ENODEV / ENXIO, the network device is gone), a kernel out of transmit buffers (ENOBUFS):
python-can raises an ``OSError``, or a ``can.CanOperationError`` carrying the errno
(socketcan: ``error_code``; its ``__cause__`` is the OSError). :class:`ReopeningBus` wraps the
master's bus and, on such an error of ``send`` or ``recv``:

* shuts the broken bus down and says so once (ERROR, with the OS reason);
* answers every ``send`` with ``can.CanOperationError("CAN interface ... lost: <reason>")``
  and every ``recv`` with nothing, so the master's cycle runs on (no station answers: the
  joints go STALE as under total frame loss) and diagnostics keep publishing;
* from the receive thread, opens the bus again after :data:`BACKOFF_FIRST_S`, the wait
  doubling after each failed attempt up to :data:`BACKOFF_MAX_S`; a failed attempt is
  logged at DEBUG, a summary at most every :data:`SUMMARY_S`; a reopened bus that fails
  before its first frame (socketcan: the device exists, its link is still down) is a failed
  attempt too;
* once a reopened bus has sent or received a frame: one line, and :attr:`on_reopen` (the
  master asks each station's supervisor to configure it again).

An error without an errno (an undecodable datagram, python-can's "Transmit buffer full"
after its own send timeout) is not a lost interface and passes through unchanged.
"""

from __future__ import annotations

import errno
import logging
import os
import threading
import time
from collections.abc import Callable

import can

from ssi_bridge.base.rate_log import RateLimitedLog

logger = logging.getLogger(__name__)

#: the first reopen attempt this long (s) after the loss; each failure doubles the wait ...
BACKOFF_FIRST_S = 0.1
#: ... up to this long (s): an interface that returns is open again within this, so the
#: stations answer again well inside 2 s (reopen + re-configuration)
BACKOFF_MAX_S = 1.0
#: while the interface stays lost, a summary line at most this often (s)
SUMMARY_S = 10.0
#: errnos python-can's socketcan carries as ``CanOperationError.error_code`` that mean the
#: interface is gone or unusable (any errno of an ``OSError`` itself counts)
LOST_ERRNOS = frozenset({errno.ENETDOWN, errno.ENODEV, errno.ENXIO, errno.ENOBUFS,
                         errno.ENETUNREACH, errno.EBADF, errno.EIO, errno.EPIPE})


def lost_reason(err: BaseException) -> str | None:
    """Why ``err`` means the interface is lost ("[Errno 100] Network is down"), or None.

    An ``OSError`` with an errno, or a ``can.CanError`` caused by one, or one whose
    ``error_code`` is in :data:`LOST_ERRNOS`.
    """
    if isinstance(err, OSError) and err.errno:
        return f"[Errno {err.errno}] {err.strerror or errno.errorcode.get(err.errno, '')}"
    if isinstance(err, can.CanError):
        cause = err.__cause__
        if isinstance(cause, OSError) and cause.errno:
            return lost_reason(cause)
        code = getattr(err, "error_code", None)
        if isinstance(code, int) and code in LOST_ERRNOS:
            return f"[Errno {code}] {os.strerror(code)} ({err})"
    return None


class ReopeningBus(can.BusABC):
    """A python-can bus that is closed when its interface is lost and opened again.

    :param inner: the open bus
    :param reopen: opens a new bus for the same interface and channel (raises on failure)
    :param name: the interface and channel, for the log and the diagnostics
    """

    def __init__(self, inner: can.BusABC, reopen: Callable[[], can.BusABC], name: str) -> None:
        self._inner: can.BusABC | None = inner
        self._reopen = reopen
        self.name = name
        #: the simulated wire under the first bus (a reopened one shares its channel's)
        self.wire = getattr(inner, "wire", None)
        self._lock = threading.Lock()
        self._closed = False
        #: why the interface is lost ("" while it works), since when (monotonic)
        self.reason = ""
        self.lost_at = 0.0
        #: losses, successful reopens and reopen attempts so far; the last attempt's error
        self.losses = 0
        self.reopens = 0
        self.attempts = 0
        self.last_attempt_error = ""
        self._delay = BACKOFF_FIRST_S
        self._next_try = 0.0
        self._tries = 0  # attempts since the last loss
        #: a reopened bus that has neither sent nor received a frame yet
        self._probation = False
        self._summary = RateLimitedLog(logger, SUMMARY_S)
        #: called once a reopened bus has sent or received a frame (the interface is back)
        self.on_reopen: Callable[[], None] | None = None
        super().__init__(channel=getattr(inner, "channel_info", name))
        self.channel_info = str(getattr(inner, "channel_info", name))

    @property
    def current(self) -> can.BusABC | None:
        """The bus open now (the opener's), None while the interface is lost."""
        return self._inner

    @property
    def lost(self) -> bool:
        """True from a loss until a reopened bus has sent or received a frame."""
        return (self._inner is None or self._probation) and not self._closed

    def problem(self) -> str:
        """The loss in words for the bus diagnostics ("" while the interface works)."""
        if not self.lost:
            return ""
        since = time.monotonic() - self.lost_at
        retry = max(0.0, self._next_try - time.monotonic())
        text = (f"CAN interface {self.name} lost {since:.1f} s ago: {self.reason}; reopening "
                f"(attempt {self._tries + 1} in {retry:.1f} s")
        last = f", last: {self.last_attempt_error}" if self.last_attempt_error else ""
        return f"{text}{last})"

    def figures(self) -> dict[str, int]:
        """Key-values for the bus diagnostics."""
        return {"interface_losses": self.losses, "interface_reopens": self.reopens,
                "interface_reopen_attempts": self.attempts}

    def _lost_error(self) -> can.CanOperationError:
        return can.CanOperationError(f"CAN interface {self.name} lost: {self.reason}")

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send ``msg``; raises ``can.CanOperationError`` while (or as) the interface is lost.

        :param timeout: as python-can's ``BusABC.send``
        """
        inner = self._inner
        if inner is None:
            raise self._lost_error()
        try:
            inner.send(msg, timeout)
        except (can.CanError, OSError) as err:
            reason = lost_reason(err)
            if reason is None:
                raise
            self._lose(inner, reason)
            raise self._lost_error() from err
        if self._probation:
            self._confirm(inner)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """One frame, or None after ``timeout``; while the interface is lost, None after
        waiting for (and making) the next reopen attempt."""
        inner = self._inner
        if inner is None:
            self._wait_and_reopen(0.05 if timeout is None else timeout)
            return None
        try:
            msg = inner.recv(timeout)
        except (can.CanError, OSError) as err:
            reason = lost_reason(err)
            if reason is None:
                raise
            self._lose(inner, reason)
            return None
        if msg is not None and self._probation:
            self._confirm(inner)
        return msg

    def _lose(self, inner: can.BusABC, reason: str) -> None:
        """``inner`` failed with ``reason``: shut it down and plan the reopen (once).

        A reopened bus that fails before it ever worked (socketcan's device exists but its
        link is still down) is a failed reopen attempt, not a new loss: the back-off goes on.
        """
        with self._lock:
            if self._inner is not inner or self._closed:
                return  # another thread saw the same loss first
            self._inner = None
            retry = self._probation
            self._probation = False
            if retry:
                self.last_attempt_error = reason
                self._delay = min(2 * self._delay, BACKOFF_MAX_S)
            else:
                self.reason = reason
                self.losses += 1
                self.lost_at = time.monotonic()
                self._delay = BACKOFF_FIRST_S
                self.last_attempt_error = ""
                self._tries = 0
            self._next_try = time.monotonic() + self._delay
        if not retry:
            logger.error("CAN interface %s lost: %s; reopening it after %g s, then with "
                         "back-off up to every %g s (the joints go STALE meanwhile)", self.name,
                         reason, BACKOFF_FIRST_S, BACKOFF_MAX_S)
        try:
            inner.shutdown()
        except Exception as err:  # noqa: BLE001 - a broken interface may fail to close too
            logger.debug("closing the lost interface %s: %r", self.name, err)

    def _wait_and_reopen(self, timeout: float) -> None:
        """Receive thread, interface lost: wait up to ``timeout`` for the next attempt, make it."""
        wait = self._next_try - time.monotonic()
        if wait > 0:
            time.sleep(min(wait, timeout))
            return
        if self._closed:
            return
        self.attempts += 1
        self._tries += 1
        try:
            bus = self._reopen()
        except Exception as err:  # noqa: BLE001 - any failure to open is retried later
            self.last_attempt_error = " ".join(str(err).split())[:200]
            self._delay = min(2 * self._delay, BACKOFF_MAX_S)
            self._next_try = time.monotonic() + self._delay
            logger.debug("CAN interface %s: reopen attempt %d failed: %s", self.name,
                         self.attempts, self.last_attempt_error)
            if time.monotonic() - self.lost_at >= SUMMARY_S:
                self._summary.warning("still_lost", "CAN interface %s still lost after %.0f s "
                                      "(%d reopen attempts; last: %s)", self.name,
                                      time.monotonic() - self.lost_at, self._tries,
                                      self.last_attempt_error)
            return
        with self._lock:
            if self._closed:
                bus.shutdown()
                return
            self._inner = bus
            self._probation = True  # until it sends or receives a frame

    def _confirm(self, inner: can.BusABC) -> None:
        """The reopened ``inner`` sent or received a frame: the interface is back."""
        with self._lock:
            if not self._probation or self._inner is not inner:
                return
            # said before ``lost`` turns False: whoever sees the interface back finds the line
            logger.warning("CAN interface %s open again after %.1f s (%d attempt(s)); "
                           "configuring the stations again", self.name,
                           time.monotonic() - self.lost_at, self._tries)
            self._probation = False
            self.reopens += 1
        if self.on_reopen is not None:
            self.on_reopen()

    def shutdown(self) -> None:
        """Shut the bus down; no reopen after this."""
        with self._lock:
            self._closed = True
            inner, self._inner = self._inner, None
        super().shutdown()
        if inner is not None:
            inner.shutdown()


__all__ = ["BACKOFF_FIRST_S", "BACKOFF_MAX_S", "LOST_ERRNOS", "ReopeningBus", "lost_reason"]
