"""The replay in a terminal: keyboard controls and a progress line.

Keys, as in rosbag2's player: space pauses and resumes, → publishes the next message while
paused, ↑ and ↓ raise and lower the rate by 10 %. The keys are read from stdin in cbreak mode
(no echo, no line buffering; Ctrl-C still interrupts) by a daemon thread, and the terminal's
settings are restored on :meth:`Keyboard.stop`. Nothing happens when stdin is not a terminal
(a pipe, a launch file, a test) or the replay runs in the background (``replay ... &``): the
keys are off and the input is never read.

The progress line (``[R] 12.345 / 60.000 s  t 1732630000.123456789  rate 1.00x  1234 msgs``)
is redrawn in place on stderr about ten times a second, only when stderr is a terminal:
``[R]`` running, ``[P]`` paused, ``[E]`` ended; the time from the start of the bag and its
length, the bag (ROS) time, the rate and the messages published so far.
"""

from __future__ import annotations

import logging
import os
import select
import sys
import threading
from typing import Any, TextIO

from ssi_bridge.record.player_state import NS, PlayerState, Snapshot

logger = logging.getLogger(__name__)

#: factors of the rate on ↑ and ↓ (rosbag2: +10 %, -10 %)
RATE_UP, RATE_DOWN = 1.1, 0.9
SPACE, RIGHT, UP, DOWN = b" ", (b"\x1b[C", b"\x1bOC"), (b"\x1b[A", b"\x1bOA"), (b"\x1b[B", b"\x1bOB")


def progress_text(snap: Snapshot) -> str:
    """One progress line (without the carriage return).

    :param snap: the time line's state
    """
    mark = "E" if snap.ended else "P" if snap.paused else "R"
    sec, nsec = divmod(snap.bag_ns, NS)
    return (f"[{mark}] {(snap.bag_ns - snap.first_ns) / NS:8.3f} / "
            f"{(snap.end_ns - snap.first_ns) / NS:.3f} s  t {sec}.{nsec:09d}  "
            f"rate {snap.rate:.2f}x  {snap.published} msgs")


class ProgressLine:
    """Draws the progress line of ``state`` on ``stream`` (a terminal) when called."""

    def __init__(self, state: PlayerState, stream: TextIO) -> None:
        self.state, self.stream = state, stream
        self.drawn = False

    def __call__(self) -> None:
        """Redraw the progress line (bag time, rate, paused) over the previous one."""
        self.stream.write("\r" + progress_text(self.state.snapshot()) + "\x1b[K")
        self.stream.flush()
        self.drawn = True

    def close(self) -> None:
        """End the line (the next output starts on a line of its own)."""
        if self.drawn:
            self.stream.write("\n")
            self.stream.flush()


def apply_key(state: PlayerState, key: bytes) -> str | None:
    """Apply one key (sequence) to ``state``; returns what it did, None for other keys."""
    if key == SPACE:
        return "pause" if state.toggle() else "resume"
    if key in RIGHT:
        return "step" if state.step() else None
    if key in UP or key in DOWN:
        state.set_rate(state.rate * (RATE_UP if key in UP else RATE_DOWN))
        return "rate"
    return None


def split_keys(data: bytes) -> list[bytes]:
    """Bytes read from the terminal as keys: escape sequences of three bytes kept whole.

    :param data: bytes read from the terminal
    """
    keys, i = [], 0
    while i < len(data):
        if data[i:i + 1] == b"\x1b" and i + 2 < len(data):
            keys.append(data[i:i + 3])
            i += 3
        else:
            keys.append(data[i:i + 1])
            i += 1
    return keys


def _foreground(fd: int) -> bool:
    """False when the replay runs in the background of its controlling terminal (changing
    the terminal's mode would stop it with SIGTTOU); True for a terminal that is not the
    controlling one (no job control there)."""
    try:
        return os.tcgetpgrp(fd) == os.getpgrp()
    except OSError:
        return True


class Keyboard:
    """Reads control keys from a terminal on stdin in a thread (see the module doc).

    :param state: the replay's time line the keys move
    :param stream: the terminal (default: stdin); nothing is read unless it is a terminal
        in the foreground
    """

    def __init__(self, state: PlayerState, stream: TextIO | None = None) -> None:
        self.state = state
        self._stream = sys.stdin if stream is None else stream
        self._saved: Any = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> bool:
        """Put the terminal in cbreak mode and start reading; False when not a terminal."""
        try:
            fd = self._stream.fileno()
        except (AttributeError, ValueError, OSError):
            return False
        if not os.isatty(fd) or not _foreground(fd):
            return False
        import termios
        import tty

        try:
            self._saved = termios.tcgetattr(fd)
            tty.setcbreak(fd)
        except termios.error as err:
            logger.warning("keyboard controls off: %s", err)
            return False
        self._thread = threading.Thread(target=self._run, args=(fd,), name="replay-keys",
                                        daemon=True)
        self._thread.start()
        return True

    def _run(self, fd: int) -> None:
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([fd], [], [], 0.1)
                if not ready:
                    continue
                data = os.read(fd, 64)
            except OSError:  # the terminal went away: keys off, the replay goes on
                return
            if not data:
                return
            for key in split_keys(data):
                try:
                    apply_key(self.state, key)
                except ValueError as err:  # a rate the time line refuses
                    logger.warning("%s", err)

    def stop(self) -> None:
        """Stop reading and give the terminal its settings back; safe to call twice."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
            self._thread = None
        if self._saved is not None:
            import termios

            try:
                termios.tcsetattr(self._stream.fileno(), termios.TCSADRAIN, self._saved)
            except (termios.error, ValueError, OSError):
                pass
            self._saved = None
