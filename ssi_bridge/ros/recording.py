"""Session recording from inside the node: the glue between the publishers and record/.

Every message the node publishes is handed to :meth:`SessionRecorder.record` right after
``publish``; while a session runs it is written to the bag with log time = publish time.
A write error (disk full, file removed) ends the session, keeps the error for the bus
diagnostics (ERROR) and never stops the publishing.

A session can be paused (messages are not written until resumed: a gap in the bag, the CAN
log goes on) and split at once into its next file (``~/pause_recording``,
``~/resume_recording``, ``~/split_recording``, as rosbag2's recorder names them; the
services are ``ros/recording_services.py``). With ``record.snapshot.duration`` every message
also goes into the fault snapshot's ring (``ros/snapshot.py``), session or not. Once the node
is finalized every start is refused. A bag's topic types and metadata:
``ros/recording_meta.py``.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rclpy.node import Node
from rclpy.qos import QoSProfile

from ssi_bridge.base.realtime import normal_this_thread
from ssi_bridge.exceptions import BusError, RecordingError
from ssi_bridge.record import cdr
from ssi_bridge.ros.params import NodeSettings
from ssi_bridge.ros.recording_meta import bus_config, session_metadata, type_of
from ssi_bridge.ros.snapshot import NodeSnapshots, node_snapshots

if TYPE_CHECKING:
    from ssi_bridge.client.sniffer import CanSniffer
    from ssi_bridge.record.bag import BagRecorder


class SessionRecorder:
    """Starts, feeds and stops one bag at a time for a node.

    :param node: the node whose clock gives the log times and whose logger says what happened
    :param settings: the node's settings at the first configure (record.*, the bus, joints)
    """

    def __init__(self, node: Node, settings: NodeSettings) -> None:
        self._node = node
        self._settings = settings
        self._lock = threading.Lock()
        self._bag: BagRecorder | None = None
        self._topics: set[str] = set()
        self._qos: dict[str, QoSProfile] = {}
        self._sniffer: CanSniffer | None = None
        #: threads finishing sessions that a write error ended (see record())
        self._salvage: list[threading.Thread] = []
        #: the last write error, shown as ERROR on the bus diagnostics until a new session
        self.error = ""
        self.sessions = 0
        #: the session's bag takes no message until resumed
        self.paused = False
        #: the node ended (lifecycle shutdown): starts are refused (set by :meth:`finalize`)
        self.finalized = False
        #: the fault snapshots (``record.snapshot.duration`` > 0), else None
        self.snapshots: NodeSnapshots | None = node_snapshots(node, settings, self._qos)
        self.open_frame_tap()

    def offer(self, topic: str, qos: QoSProfile) -> None:
        """Record ``topic`` with the QoS its publisher offers (rosbag2 stores it per channel)."""
        self._qos[topic] = qos

    @property
    def active(self) -> bool:
        """True while a session is being written."""
        return self._bag is not None

    def start(self, requested: str = "") -> Path:
        """Open a new bag under ``record.root`` (``requested``: its name or path; empty: a
        timestamped name); returns its directory.

        :raises RecordingError: finalized, a session already runs, the root cannot be made,
            the bag cannot be opened
        :raises ValueError: ``requested`` is not a usable bag name
        """
        from ssi_bridge.record.bag import BagRecorder
        from ssi_bridge.record.session import resolve_bag_path

        with self._lock:
            if self.finalized:
                raise RecordingError(
                    "the node is finalized (lifecycle shutdown): its bus and cycle are closed, "
                    "a bag would stay empty; start a new node to record")
            if self._bag is not None:
                raise RecordingError(
                    f"a recording is already running in {self._bag.directory}; stop it first")
            root = Path(self._settings.record_root).expanduser()
            try:
                root.mkdir(parents=True, exist_ok=True)
            except OSError as err:
                raise RecordingError(f"cannot create recording root {root}: {err}") from err
            path = resolve_bag_path(root, requested)
            metadata = session_metadata(self._settings)
            self._bag = BagRecorder.open(path, compression=self._settings.record_compression,
                                         metadata=metadata,
                                         max_size=self._settings.record_max_size,
                                         max_duration_s=self._settings.record_max_duration)
            self._topics = set()
            if self._settings.record_can_log:
                self._start_sniffer(path)
            self.error = ""
            self.paused = False
            self.sessions += 1
        self._node.get_logger().info(f"recording to {path}")
        return path

    def stop(self) -> tuple[Path, int] | None:
        """Close the running bag; returns (directory, messages) or None if none ran.

        A session ended by a write error is finished first (its bag rebuilt), so that a
        shutdown right after it leaves no half-written file behind.

        :raises RecordingError: the bag could not be closed (the error is kept for the
            diagnostics)
        """
        while self._salvage:
            self._salvage.pop().join()
        with self._lock:
            bag, self._bag = self._bag, None
            sniffer, self._sniffer = self._sniffer, None
        if sniffer is not None:
            frames = sniffer.stop()
            self._node.get_logger().info(
                f"CAN log closed: {sniffer.path} ({frames} frames"
                + (f"; stopped early: {sniffer.error})" if sniffer.error else ")"))
        if bag is None:
            return None
        try:
            summary = bag.close()
        except (RecordingError, OSError) as err:
            self.error = f"recording stopped: {err}"
            self._node.get_logger().error(self.error)
            raise RecordingError(self.error) from err
        self._node.get_logger().info(
            f"recording closed: {summary.directory} ({summary.message_count} messages)")
        return Path(summary.directory), summary.message_count

    @property
    def capturing(self) -> bool:
        """True while :meth:`record` keeps messages (a session, or the snapshot ring)."""
        return self._bag is not None or self.snapshots is not None

    def record(self, topic: str, msg: Any, stamp_ns: int) -> None:
        """Keep one published message: in the snapshot ring (if on) and in the session's bag
        if one runs and is not paused; a write error ends the session."""
        bag = None if self.paused else self._bag
        snapshots = self.snapshots
        if bag is None and snapshots is None:
            return
        data = cdr.serialize(msg)
        now_ns = self._node.get_clock().now().nanoseconds  # the bag keeps log times in order
        if snapshots is not None:
            try:
                snapshots.keep(topic, msg, data, now_ns, stamp_ns)
            except Exception as err:  # noqa: BLE001 - a snapshot never stops the publishing
                self._node.get_logger().error(f"fault snapshot: {type(err).__name__}: {err}",
                                              throttle_duration_sec=1.0)
        if bag is None:
            return
        try:
            if topic not in self._topics:
                bag.add_topic(topic, type_of(topic), self._qos.get(topic))
                self._topics.add(topic)
            bag.write_serialized(topic, data, log_time_ns=now_ns, publish_time_ns=stamp_ns)
        except (RecordingError, OSError) as err:
            self.error = f"recording stopped: {err}"
            self._node.get_logger().error(self.error)
            with self._lock:
                self._bag = None
                sniffer, self._sniffer = self._sniffer, None
            # closing the CAN log and rebuilding the bag take time: not in the cycle thread
            worker = threading.Thread(target=self._end_failed_session, args=(bag, sniffer),
                                      name="recording-salvage", daemon=True)
            self._salvage.append(worker)
            worker.start()

    def _end_failed_session(self, bag: BagRecorder, sniffer: CanSniffer | None) -> None:
        """After a bag write error: close the CAN log, then give the bag its summary with
        ``recover`` so it stays readable; without room for that copy it is left for
        ``replay --recover`` (said in the log)."""
        from ssi_bridge.record.recover import recover_bag

        normal_this_thread()  # started by the cycle thread: not at its real-time priority
        if sniffer is not None:
            frames = sniffer.stop()
            self._node.get_logger().info(f"CAN log closed: {sniffer.path} ({frames} frames)")
        try:
            bag.close()
        except (RecordingError, OSError):
            pass  # expected: the bag is in its failed state
        try:
            summary = recover_bag(bag.directory)
        except (RecordingError, OSError) as err:
            self._node.get_logger().warning(
                f"bag {bag.directory} left without summary: {err}; `replay --recover "
                f"{bag.directory}` rebuilds it once there is room")
            return
        self._node.get_logger().info(
            f"bag {bag.directory} rebuilt after the write error: {summary.message_count} "
            f"messages readable")

    def counters(self) -> dict[str, object]:
        """Recording figures for the bus diagnostics."""
        bag, sniffer = self._bag, self._sniffer
        out: dict[str, object] = {
            "recording": int(bag is not None), "is_paused": bag is not None and self.paused,
            "recorded_messages": bag.message_count if bag is not None else 0,
            "recorded_files": len(bag.files) if bag is not None else 0,
            "can_frames_logged": sniffer.frames if sniffer is not None else 0}
        if self.snapshots is not None:
            out.update(self.snapshots.counters())
        return out

    def _start_sniffer(self, bag_dir: Path) -> None:
        """Log the raw CAN traffic beside the bag (``can_0.log``, candump format)."""
        from ssi_bridge.client.sniffer import CanSniffer

        try:
            self._sniffer = CanSniffer(bus_config(self._settings), bag_dir / "can_0.log",
                                       on_error=self._on_can_log_error)
        except BusError as err:
            # the bag still records; the reason shows on the bus diagnostics
            self.error = f"CAN log not written: {err}"
            self._node.get_logger().error(self.error)

    def _on_can_log_error(self, reason: str) -> None:
        """The CAN log hit a write error (sniffer thread): ERROR on the bus diagnostics at once
        (the node checks :attr:`error` every cycle); the bag goes on recording."""
        self.error = reason

    # -- recorder control (rosbag2's pause / resume / split_bagfile) --------------------------
    def set_paused(self, paused: bool) -> str:
        """Pause or resume the running session; returns what was done. Pausing a paused
        session (or resuming a running one) changes nothing.

        :raises RecordingError: no session runs
        """
        with self._lock:
            bag = self._bag
            if bag is None:
                raise RecordingError("no recording is running")
            was, self.paused = self.paused, paused
        if was == paused:
            return f"{bag.directory} already {'paused' if paused else 'recording'}"
        text = (f"recording to {bag.directory} paused: messages are not written until "
                "~/resume_recording" if paused else f"recording to {bag.directory} resumed")
        self._node.get_logger().info(text)
        return text

    def split(self) -> Path:
        """Close the session's open file and go on in the next ``<bag>_<k>.mcap`` at once;
        returns its path.

        :raises RecordingError: no session runs, or nothing was written to the open file
        """
        bag = self._bag
        if bag is None:
            raise RecordingError("no recording is running")
        path = bag.directory / bag.split()
        self._node.get_logger().info(f"recording split: now writing {path}")
        return path

    def finalize(self) -> tuple[Path, int] | None:
        """The node ends (lifecycle shutdown, process exit): stop the session, finish the
        snapshot being written, and refuse every later start."""
        self.finalized = True
        try:
            return self.stop()
        finally:
            if self.snapshots is not None:
                self.snapshots.close()

    def open_frame_tap(self) -> None:
        """Snapshots with ``record.can_log``: listen on the node's bus for the frames' ring
        (each configure); a bus that cannot be opened leaves the messages' ring running."""
        if self.snapshots is None or self.finalized:
            return
        try:
            self.snapshots.open_frame_tap()
        except BusError as err:
            self.error = f"snapshot CAN ring not kept: {err}"
            self._node.get_logger().error(self.error)

    def close_frame_tap(self) -> None:
        """Stop listening on the bus (cleanup closes the bus side; the ring keeps its frames)."""
        if self.snapshots is not None:
            self.snapshots.close_frame_tap()


__all__ = ["SessionRecorder"]
