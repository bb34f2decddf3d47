"""Stop signals a program handles without ever being interrupted by them (ROS-free).

A Python signal handler runs in the main thread between two bytecodes, possibly inside a
lock the main thread holds (``threading.Event.set``/``wait``) or inside a shutdown step; a
second signal (``ros2 launch`` forwards the terminal's Ctrl-C, PR_SET_PDEATHSIG, a node
stopping its station) may land inside the first one's handler. So the handler does nothing,
and a watcher thread woken through ``signal.set_wakeup_fd`` acts on the signal.
"""

from __future__ import annotations

import signal
import socket
import threading
from collections.abc import Callable

#: the stop signals a launch system or a terminal sends
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopRequests:
    """Stop signals, seen by a watcher thread through ``signal.set_wakeup_fd``.

    The Python-level handler does nothing (it only has to exist so that CPython's C handler
    writes the signal number to the wake-up socket); the watcher thread sets :attr:`event`
    and calls the ``on_stop`` callbacks once, at the first signal.
    """

    def __init__(self) -> None:
        self.event = threading.Event()
        self.signum = 0
        self._callbacks: list[Callable[[], None]] = []
        self._lock = threading.Lock()
        self._reader, self._writer = socket.socketpair()
        self._writer.setblocking(False)

    @property
    def requested(self) -> bool:
        """True once a stop signal (or :meth:`request`) arrived."""
        return self.event.is_set()

    def install(self, watch: bool = True) -> None:
        """Route SIGINT and SIGTERM to the watcher (main thread only); ``watch=False`` leaves
        starting the watcher thread to :meth:`watch` (signals meanwhile wait for it)."""
        for sig in STOP_SIGNALS:
            signal.signal(sig, _ignore)
        signal.set_wakeup_fd(self._writer.fileno(), warn_on_full_buffer=False)
        if watch:
            self.watch()

    def ignore_further(self) -> None:
        """From now on the kernel discards stop signals: for a program that is ending (main
        thread only).

        The interpreter's finalization puts every signal with a Python handler back to its
        default action, so one signal of a storm landing in the last moments of an ending
        program would kill it by that signal instead of letting it exit 0. An ignored signal
        stays ignored through finalization.
        """
        for sig in STOP_SIGNALS:
            signal.signal(sig, signal.SIG_IGN)

    def watch(self) -> None:
        """Start the watcher thread (once)."""
        threading.Thread(target=self._watch, name="stop-signals", daemon=True).start()

    def on_stop(self, callback: Callable[[], None]) -> None:
        """Call ``callback`` at the first stop (at once if it already happened)."""
        with self._lock:
            if not self.event.is_set():
                self._callbacks.append(callback)
                return
        callback()

    def request(self) -> None:
        """Stop as if a signal had arrived (e.g. the end of a replayed log)."""
        with self._lock:
            if self.event.is_set():
                return
            self.event.set()
            callbacks, self._callbacks = self._callbacks, []
        for callback in callbacks:
            callback()

    def _watch(self) -> None:
        while True:
            data = self._reader.recv(64)
            if not data:
                return
            if not self.event.is_set():
                self.signum = data[0]
                self.request()


def _ignore(_signum: int, _frame: object) -> None:
    """The Python side of a stop signal: nothing (the watcher thread acts on it)."""
