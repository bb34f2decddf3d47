"""Fault snapshots: the last N seconds before a fault and the next ones after it, as a bag.

:class:`SnapshotKeeper` keeps every recorded message (CDR bytes) in a
:class:`~ssi_bridge.record.ring.MessageRing` of ``duration_s``. :meth:`~SnapshotKeeper.trigger`
(a joint or the bus went ERROR, or ``~/snapshot``) writes the ring as a complete bag
``snapshot_<YYYY_MM_DD-HH_MM_SS>_<label>/`` under the recording root (a normal session
directory, metadata.yaml included) and goes on writing the messages of the next ``after_s``
seconds into it. A trigger while a snapshot is still taking messages extends it to
``after_s`` past the new trigger instead of starting another bag; once ``max_bags``
snapshots are on disk, the oldest is removed (and the log says so).

Threads: :meth:`add` and :meth:`trigger` run on the publishing threads (the 1 kHz cycle
among them) and only copy references under a lock; each snapshot's bag is opened, written
and closed by a thread of its own, which takes the ring's copy and then the live messages
from a queue. The ring and the queue are bounded by time (``duration_s``, ``after_s`` past
the last trigger). ROS-free: the bag comes from an ``open_bag`` callable, a topic's type
and QoS from ``topic_info``.

With ``can_log`` a second ring of the same duration holds the raw CAN frames
(:meth:`SnapshotKeeper.add_frame`, ``record/can_frames.py``; time = the frame's wire time, the
same clock as the node's log time), written beside the bag as ``can_0.log`` (candump), as a
session's ``record.can_log`` does. The frames come through a listener of their own, which may
lag the messages: the CAN log takes frames until one stamped after the snapshot's end comes
(at most ``FRAME_GRACE_S`` after its messages ended).
"""

from __future__ import annotations

import logging
import re
import shutil
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from ssi_bridge.base.realtime import normal_this_thread
from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record.can_frames import FrameLog
from ssi_bridge.record.metadata import METADATA_FILE
from ssi_bridge.record.ring import MessageRing

if TYPE_CHECKING:  # the bag is opened by the caller's ``open_bag``; snapshot stays ROS-free
    from rclpy.qos import QoSProfile

    from ssi_bridge.record.bag import BagRecorder

logger = logging.getLogger(__name__)

#: a snapshot bag's directory name: prefix, local time as rosbag2 names bags, then the label
PREFIX = "snapshot_"
TIME_FORMAT = "%Y_%m_%d-%H_%M_%S"
#: longest label in a directory name (a joint's name may be long)
LABEL_MAX = 64
#: the CAN log of a snapshot, as a session's (record.can_log)
CAN_LOG = "can_0.log"
#: longest wait (s) after a snapshot's messages end for its CAN frames to catch up (the
#: frames come through a listener of their own, which a loaded machine may hold back)
FRAME_GRACE_S = 1.0

#: opens a new bag at a path (BagRecorder.open with the session's settings)
OpenBag = Callable[[Path], "BagRecorder"]
#: a topic's (type name ``pkg/msg/Type``, offered QoS or None)
TopicInfo = Callable[[str], tuple[str, "QoSProfile | None"]]


class Log(Protocol):
    """Where a snapshot's outcome is logged (a ``logging.Logger`` or rclpy's node logger)."""

    def info(self, message: str) -> object:
        """Log ``message`` at INFO."""

    def warning(self, message: str) -> object:
        """Log ``message`` at WARNING."""

    def error(self, message: str) -> object:
        """Log ``message`` at ERROR."""


@dataclass(frozen=True)
class SnapshotConfig:
    """``record.snapshot.*``: ring length, what follows a trigger, when, how many bags.

    :raises ValueError: a value out of range
    """

    root: Path
    #: seconds kept before a trigger (> 0)
    duration_s: float
    #: seconds recorded after the last trigger of a snapshot
    after_s: float = 5.0
    #: write a snapshot when a joint or the bus reaches ERROR
    on_error: bool = True
    #: snapshot bags kept under root; the oldest beyond this is removed
    max_bags: int = 10
    #: also keep the raw CAN frames (:meth:`SnapshotKeeper.add_frame`), written as can_0.log
    can_log: bool = False

    def __post_init__(self) -> None:
        if not self.duration_s > 0:
            raise ValueError(f"snapshot duration {self.duration_s}: must be > 0 s")
        if self.after_s < 0:
            raise ValueError(f"snapshot after {self.after_s}: must be >= 0 s")
        if self.max_bags < 1:
            raise ValueError(f"snapshot max_bags {self.max_bags}: at least 1")


def label_of(text: str) -> str:
    """``text`` as a directory-name part: letters, digits, ``_.-`` (others ``_``), cut short."""
    return re.sub(r"[^A-Za-z0-9_.-]", "_", text.strip())[:LABEL_MAX] or "snapshot"


@dataclass
class _Snapshot:
    """One snapshot bag while it takes messages."""

    path: Path
    until_ns: int
    triggers: list[str]
    queue: deque[Any] = field(default_factory=deque)
    #: CAN frames (ring bytes) that arrived after the trigger
    frame_queue: deque[bytes] = field(default_factory=deque)
    #: no more messages go in (the time after the last trigger is over, or a stop)
    ended: bool = False
    #: a CAN frame stamped after ``until_ns`` arrived: the frames up to it are all in
    frames_caught_up: bool = False


class SnapshotKeeper:
    """The ring, the snapshot being written, and the snapshot bags on disk (module docstring).

    :param clock_ns: the log-time clock (the node's), in ns; ends a snapshot without messages

    :param config: duration before and after, root, bag limits, CAN log
    :param open_bag: opens a snapshot's bag at a path
    :param topic_info: a topic's type name and offered QoS
    :param log: where a snapshot's outcome is logged
    """

    def __init__(self, config: SnapshotConfig, open_bag: OpenBag, topic_info: TopicInfo,
                 clock_ns: Callable[[], int] = time.time_ns,
                 log: Log = logger) -> None:
        self.config = config
        self.ring = MessageRing(config.duration_s)
        #: the raw CAN frames (``can_log``), else None
        self.frames = MessageRing(config.duration_s) if config.can_log else None
        self._open_bag = open_bag
        self._topic_info = topic_info
        self._clock_ns = clock_ns
        self._log = log
        self._cond = threading.Condition()
        self._active: _Snapshot | None = None
        #: the snapshot taking CAN frames: the tap's receive path may lag the messages, so
        #: it stays open past the messages' end until a frame after ``until_ns`` comes
        self._frame_snap: _Snapshot | None = None
        self._threads: list[threading.Thread] = []
        #: snapshot bags written (complete) and triggers that extended one
        self.written = 0
        self.extended = 0
        #: the last snapshot's write error ("" none)
        self.error = ""
        self.last_path: Path | None = None

    # -- the publishing threads ----------------------------------------------------------------
    def add(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int) -> None:
        """One recorded message: into the ring, and into the open snapshot while it runs.

        :param topic: the message's topic
        :param data: its CDR bytes
        :param log_time_ns: when it was received (ns)
        :param publish_time_ns: when it was sent (ns)
        """
        with self._cond:
            self.ring.append(topic, log_time_ns, publish_time_ns, data)
            snap = self._active
            if snap is None:
                return
            if log_time_ns > snap.until_ns:
                self._end(snap)
            else:
                snap.queue.append((topic, log_time_ns, publish_time_ns, data))
                self._cond.notify_all()

    def add_frame(self, wire_time_ns: int, data: bytes) -> None:
        """One CAN frame (``record/can_frames.pack_frame``): into the frame ring, and into the
        open snapshot while it runs (ignored without ``can_log``).

        :param wire_time_ns: the frame's wire time (ns)
        :param data: the packed frame
        """
        if self.frames is None:
            return
        with self._cond:
            self.frames.append("can", wire_time_ns, wire_time_ns, data)
            snap = self._frame_snap
            if snap is None:
                return
            if wire_time_ns <= snap.until_ns:
                snap.frame_queue.append(data)
            elif not snap.frames_caught_up:
                snap.frames_caught_up = True
                self._cond.notify_all()

    def trigger(self, label: str, now_ns: int | None = None) -> tuple[Path, bool]:
        """Write a snapshot at ``now_ns`` (log time; default the clock), named after ``label``.

        Returns (bag directory, extended): True when a snapshot still taking messages was
        extended to ``after_s`` past this trigger instead of a new bag being started.
        """
        now_ns = self._clock_ns() if now_ns is None else now_ns
        until = now_ns + int(self.config.after_s * 1e9)
        with self._cond:
            snap = self._active
            if snap is not None and not snap.ended:
                snap.until_ns = max(snap.until_ns, until)
                snap.frames_caught_up = False
                snap.triggers.append(label)
                self.extended += 1
                return snap.path, True
            snap = _Snapshot(self._new_path(label), until, [label])
            self._active = snap
            if self.frames is not None:
                if self._frame_snap is not None:  # the last one's frames: no longer awaited
                    self._frame_snap.frames_caught_up = True
                self._frame_snap = snap
            topics, entries = self.ring.raw()
            frames = [e[3] for e in self.frames.raw()[1]] if self.frames is not None else None
            worker = threading.Thread(target=self._write, args=(snap, topics, entries, frames),
                                      name="snapshot-writer", daemon=True)
            self._threads = [t for t in self._threads if t.is_alive()] + [worker]
        worker.start()
        return snap.path, False

    def counters(self) -> dict[str, int | str]:
        """Figures for the bus diagnostics: the ring's memory and the snapshots."""
        with self._cond:
            return {"snapshot_ring_bytes": self.ring.memory_bytes,
                    "snapshot_ring_messages": len(self.ring),
                    "snapshot_ring_s": f"{self.ring.span_ns / 1e9:.1f}",
                    "snapshot_writing": int(self._active is not None and not self._active.ended),
                    "snapshots_written": self.written,
                    **({"snapshot_can_ring_bytes": self.frames.memory_bytes}
                       if self.frames is not None else {})}

    def close(self, timeout: float = 30.0) -> None:
        """End the snapshot being written now (node shutdown) and wait for its bag to close.

        :param timeout: longest wait for the bag to close (s)
        """
        with self._cond:
            if self._active is not None:
                self._end(self._active)
            if self._frame_snap is not None:  # its frames are not waited for
                self._frame_snap.frames_caught_up = True
                self._cond.notify_all()
            threads, self._threads = self._threads, []
        for worker in threads:
            worker.join(timeout)

    # -- the writer thread ---------------------------------------------------------------------
    def _end(self, snap: _Snapshot) -> None:
        """No more messages into ``snap`` (called with the lock held)."""
        snap.ended = True
        if self._active is snap:
            self._active = None
        self._cond.notify_all()

    def _new_path(self, label: str) -> Path:
        """A new snapshot directory name under the root (not created here)."""
        base = f"{PREFIX}{datetime.now().strftime(TIME_FORMAT)}_{label_of(label)}"
        path, n = self.config.root / base, 1
        while path.exists():
            path, n = self.config.root / f"{base}_{n}", n + 1
        return path

    def _write(self, snap: _Snapshot, topics: list[str], entries: list[Any],
               frames: list[bytes] | None) -> None:
        """Open the bag (and the CAN log), write the rings' copies, then the queued messages
        and frames until the snapshot ends; close them and keep at most ``max_bags``. Errors
        end up in the log and :attr:`error`, never in the publishing threads."""
        normal_this_thread()  # started by the cycle thread: not at its real-time priority
        try:
            self.config.root.mkdir(parents=True, exist_ok=True)
            bag = self._open_bag(snap.path)
        except (RecordingError, OSError) as err:
            self._failed(snap, f"snapshot {snap.path.name} not written: {err}")
            return
        added: set[str] = set()
        can_log: FrameLog | None = None
        try:
            if frames is not None:
                can_log = FrameLog(snap.path / CAN_LOG)
                can_log.write(frames)
                del frames
            self._put(bag, added, [(topics[i], lt, pt, d) for i, lt, pt, d in entries])
            del entries
            while True:
                with self._cond:
                    while not snap.queue and not snap.ended:
                        if self._clock_ns() > snap.until_ns:
                            self._end(snap)
                            break
                        self._cond.wait(0.2)
                    batch, more = list(snap.queue), list(snap.frame_queue)
                    snap.queue.clear()
                    snap.frame_queue.clear()
                if can_log is not None:
                    can_log.write(more)
                if batch:
                    self._put(bag, added, batch)
                elif snap.ended:
                    break
            if can_log is not None:
                can_log.write(self._last_frames(snap))
                can_log.close()
            summary = bag.close()
        except (RecordingError, OSError, ValueError) as err:
            self._failed(snap, f"snapshot {snap.path} stopped: {err}")
            for done in (can_log, bag):
                try:
                    if done is not None:
                        done.close()
                except (RecordingError, OSError, ValueError):
                    pass  # the failed bag: `replay --recover` rebuilds what was written
            return
        self.written += 1
        self.last_path = snap.path
        self._log.info(f"snapshot written: {snap.path} ({summary.message_count} messages, "
                       f"{summary.duration:.1f} s"
                       + (f", {can_log.frames} CAN frames" if can_log is not None else "")
                       + f"; {len(snap.triggers)} trigger(s): "
                       f"{', '.join(snap.triggers)})")
        self._prune(snap.path)

    def _last_frames(self, snap: _Snapshot) -> list[bytes]:
        """The CAN frames still owed to ``snap`` once its messages ended: those its tap
        receives until one stamped after ``until_ns`` comes (at most FRAME_GRACE_S)."""
        deadline = time.monotonic() + FRAME_GRACE_S
        with self._cond:
            while not snap.frames_caught_up and time.monotonic() < deadline:
                self._cond.wait(0.05)
            if self._frame_snap is snap:
                self._frame_snap = None
            more = list(snap.frame_queue)
            snap.frame_queue.clear()
        return more

    def _put(self, bag: BagRecorder, added: set[str], items: list[Any]) -> None:
        for topic, log_ns, pub_ns, data in items:
            if topic not in added:
                type_name, qos = self._topic_info(topic)
                bag.add_topic(topic, type_name, qos)
                added.add(topic)
            bag.write_serialized(topic, data, log_ns, pub_ns)

    def _failed(self, snap: _Snapshot, message: str) -> None:
        with self._cond:
            self._end(snap)
            snap.queue.clear()
            if self._frame_snap is snap:
                self._frame_snap = None
            snap.frame_queue.clear()
        self.error = message
        self._log.error(message)

    def _prune(self, keep: Path) -> None:
        """Remove the oldest snapshot bags beyond ``max_bags`` (never ``keep``)."""
        root = self.config.root
        try:
            bags = sorted((p for p in root.iterdir() if p.name.startswith(PREFIX)
                           and p.is_dir() and (p / METADATA_FILE).exists()),
                          key=lambda p: (p.stat().st_mtime, p.name))
        except OSError as err:
            self._log.warning(f"snapshot bags under {root} not counted: {err}")
            return
        excess = len(bags) - self.config.max_bags
        for old in [p for p in bags if p != keep][:max(0, excess)]:
            shutil.rmtree(old, ignore_errors=True)
            self._log.info(f"removed the oldest snapshot {old} (record.snapshot.max_bags: "
                           f"{self.config.max_bags})")
