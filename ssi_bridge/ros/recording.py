"""Session recording from inside the node: the glue between the publishers and record/.

Every message the node publishes is handed to :meth:`SessionRecorder.record` right after
``publish``; while a session runs it is written to the bag with log time = publish time.
A write error (disk full, file removed) ends the session, keeps the error for the bus
diagnostics (ERROR) and never stops the publishing.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ssi_bridge import __version__
from ssi_bridge.exceptions import BusError, RecordingError
from ssi_bridge.base.realtime import normal_this_thread

if TYPE_CHECKING:
    from rclpy.node import Node

    from ssi_bridge.client.sniffer import CanSniffer
    from ssi_bridge.record.bag import BagRecorder
    from ssi_bridge.ros.params import NodeSettings

#: type of every topic the node records, by the suffix of its resolved name
TOPIC_TYPES = {
    "joint_states": "sensor_msgs/msg/JointState",
    "status": "ssi_bridge_msgs/msg/Status",
    "events": "ssi_bridge_msgs/msg/Event",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}


class SessionRecorder:
    """Starts, feeds and stops one bag at a time for a node."""

    def __init__(self, node: Node, settings: NodeSettings) -> None:
        self._node = node
        self._settings = settings
        self._lock = threading.Lock()
        self._bag: BagRecorder | None = None
        self._topics: set[str] = set()
        self._qos: dict[str, Any] = {}
        self._sniffer: CanSniffer | None = None
        #: threads finishing sessions that a write error ended (see record())
        self._salvage: list[threading.Thread] = []
        #: the last write error, shown as ERROR on the bus diagnostics until a new session
        self.error = ""
        self.sessions = 0

    def offer(self, topic: str, qos: Any) -> None:
        """Record ``topic`` with the QoS its publisher offers (rosbag2 stores it per channel)."""
        self._qos[topic] = qos

    @property
    def active(self) -> bool:
        """True while a session is being written."""
        return self._bag is not None

    def start(self, requested: str = "") -> Path:
        """Open a new bag under ``record.root``; raises RecordingError with the reason."""
        from ssi_bridge.record.bag import BagRecorder
        from ssi_bridge.record.session import resolve_bag_path

        with self._lock:
            if self._bag is not None:
                raise RecordingError(
                    f"a recording is already running in {self._bag.directory}; stop it first")
            root = Path(self._settings.record_root).expanduser()
            try:
                root.mkdir(parents=True, exist_ok=True)
            except OSError as err:
                raise RecordingError(f"cannot create recording root {root}: {err}") from err
            path = resolve_bag_path(root, requested)
            metadata = self._metadata()
            self._bag = BagRecorder.open(path, compression=self._settings.record_compression,
                                         metadata=metadata,
                                         max_size=self._settings.record_max_size,
                                         max_duration_s=self._settings.record_max_duration)
            self._topics = set()
            if self._settings.record_can_log:
                self._start_sniffer(path)
            self.error = ""
            self.sessions += 1
        self._node.get_logger().info(f"recording to {path}")
        return path

    def stop(self) -> tuple[Path, int] | None:
        """Close the running bag; returns (directory, messages) or None if none ran.

        A session ended by a write error is finished first (its bag rebuilt), so that a
        shutdown right after it leaves no half-written file behind.
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

    def record(self, topic: str, msg: Any, stamp_ns: int) -> None:
        """Write one published message if a session runs; a write error ends the session."""
        bag = self._bag
        if bag is None:
            return
        try:
            if topic not in self._topics:
                bag.add_topic(topic, self._type_of(topic), self._qos.get(topic))
                self._topics.add(topic)
            now_ns = self._node.get_clock().now().nanoseconds
            bag.write(topic, msg, log_time_ns=now_ns, publish_time_ns=stamp_ns)
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

    def counters(self) -> dict[str, int]:
        """Recording figures for the bus diagnostics."""
        bag, sniffer = self._bag, self._sniffer
        return {"recording": int(bag is not None),
                "recorded_messages": bag.message_count if bag is not None else 0,
                "recorded_files": len(bag.files) if bag is not None else 0,
                "can_frames_logged": sniffer.frames if sniffer is not None else 0}

    def _start_sniffer(self, bag_dir: Path) -> None:
        """Log the raw CAN traffic beside the bag (``can_0.log``, candump format)."""
        from ssi_bridge.client.sniffer import CanSniffer
        from ssi_bridge.protocol.settings import BusConfig

        s = self._settings
        config = BusConfig(interface=s.bus_interface, channel=s.bus_channel,
                           bitrate=s.bus_bitrate, node_id=s.node_id)
        try:
            self._sniffer = CanSniffer(config, bag_dir / "can_0.log",
                                       on_error=self._on_can_log_error)
        except BusError as err:
            # the bag still records; the reason shows on the bus diagnostics
            self.error = f"CAN log not written: {err}"
            self._node.get_logger().error(self.error)

    def _on_can_log_error(self, reason: str) -> None:
        """The CAN log hit a write error (sniffer thread): ERROR on the bus diagnostics at once
        (the node checks :attr:`error` every cycle); the bag goes on recording."""
        self.error = reason

    def on_start(self, request: Any, response: Any) -> Any:
        """~/start_recording."""
        try:
            response.bag_directory = str(self.start(request.path))
            response.success, response.message = True, f"recording to {response.bag_directory}"
        except (RecordingError, OSError, ValueError) as err:
            response.success, response.message = False, f"start_recording: {err}"
        return response

    def on_stop(self, request: Any, response: Any) -> Any:
        """~/stop_recording."""
        try:
            done = self.stop()
        except (RecordingError, OSError) as err:
            response.success, response.message = False, f"stop_recording: {err}"
            return response
        if done is None:
            response.success, response.message = False, "stop_recording: no recording is running"
            return response
        response.bag_directory, response.message_count = str(done[0]), done[1]
        response.success = True
        response.message = f"closed {done[0]} with {done[1]} messages"
        return response

    def _type_of(self, topic: str) -> str:
        for suffix, type_name in TOPIC_TYPES.items():
            if topic == suffix or topic.endswith("/" + suffix.lstrip("/")):
                return type_name
        raise RecordingError(f"no message type known for topic {topic}")

    def _metadata(self) -> dict[str, str]:
        s = self._settings
        meta = {"package_version": __version__, "bus": f"{s.bus_interface}:{s.bus_channel}",
                "bus_bitrate": str(s.bus_bitrate), "node_id": str(s.node_id),
                "stations": ",".join(str(i) for i in s.station_ids),
                "simulation": str(s.simulation), "publish_rate": f"{s.publish_rate:g}",
                "can_log": "can_0.log" if s.record_can_log else ""}
        for j in s.joints:
            meta[f"joint.{j.name}"] = (f"station={j.station or s.node_id} slot={j.slot} "
                                       f"family={j.family} "
                                       f"para1=0x{j.para1:08X}")
        return meta
