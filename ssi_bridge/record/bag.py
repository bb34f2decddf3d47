"""Record rclpy messages into a rosbag2-compatible MCAP bag directory.

Layout as rosbag2 (storage plugin ``mcap``) writes it: ``<dir>/<dirname>_0.mcap`` with
profile ``ros2``, one ``ros2msg`` schema per type, ``cdr`` channels carrying
``offered_qos_profiles`` and ``topic_type_hash``, zstd/lz4 chunks with message indexes and a
summary with statistics, a ``rosbag2`` metadata record; and ``<dir>/metadata.yaml``.

Crash safety: a background thread closes the open chunk and flushes the file every
``flush_period_s`` (0.5 s), so a kill -9 loses at most that much; ``recover.recover_bag``
rebuilds the summary and metadata.yaml. Any OSError (disk full, EFBIG, EIO) turns the
recorder into a failed state and surfaces as :class:`RecordingError` on the next call, so the
node can stop recording and report ERROR while it keeps publishing.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

from mcap.writer import CompressionType, Writer
from rclpy.qos import QoSProfile

from ssi_bridge import __version__
from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record import cdr
from ssi_bridge.record.metadata import ROS_DISTRO, BagInfo, TopicInfo, metadata_text, write_metadata
from ssi_bridge.record.qos import qos_text
from ssi_bridge.record.schema import build_schema

logger = logging.getLogger(__name__)

COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
                "none": CompressionType.NONE, "": CompressionType.NONE}
#: default QoS of a topic added without one (rclpy's default publisher profile)
DEFAULT_QOS = QoSProfile(depth=10)
#: name of the MCAP metadata record holding the session configuration
CONFIG_METADATA_NAME = "ssi_bridge"


@dataclass(frozen=True)
class BagSummary:
    """Result of :meth:`BagRecorder.close`."""

    directory: Path
    message_count: int
    #: log-time span of the recorded messages (s)
    duration: float
    topics: dict[str, int] = field(default_factory=dict)


@dataclass
class _Channel:
    """One registered topic."""

    channel_id: int
    info: TopicInfo
    sequence: int = 0


class BagRecorder:
    """Write one bag; thread-safe ``write`` from any thread (e.g. the node's 1 kHz timer)."""

    def __init__(self, directory: Path, stream: BinaryIO, writer: Writer, info: BagInfo,
                 flush_period_s: float) -> None:
        self._directory = directory
        self._stream = stream
        self._writer = writer
        self._info = info
        self._lock = threading.Lock()
        self._channels: dict[str, _Channel] = {}
        self._schemas: dict[str, int] = {}
        self._dirty = False
        self._error: RecordingError | None = None
        self._closed = False
        self._stop = threading.Event()
        self._flush_period = flush_period_s
        self._flusher = threading.Thread(target=self._flush_loop, name="bag-flush", daemon=True)
        self._flusher.start()

    @classmethod
    def open(cls, directory: Path, *, compression: str = "zstd",
             metadata: dict[str, str] | None = None, flush_period_s: float = 0.5,
             chunk_size: int = 1024 * 1024) -> BagRecorder:
        """Create the bag directory and its MCAP file; refuse an existing or unwritable one."""
        directory = Path(directory).absolute()
        if compression not in COMPRESSIONS:
            raise RecordingError(f"compression {compression!r}: expected zstd, lz4 or none")
        if directory.exists():
            raise RecordingError(f"bag directory {directory} already exists; choose a new name")
        file_name = f"{directory.name}_0.mcap"
        try:
            directory.mkdir(parents=True)
            stream = open(directory / file_name, "xb")  # noqa: SIM115 - closed in close()
        except OSError as err:
            raise RecordingError(f"cannot create bag {directory}: {err.strerror or err}") from err
        writer = Writer(stream, chunk_size=chunk_size, compression=COMPRESSIONS[compression])
        info = BagInfo(file_name, custom_data={str(k): str(v) for k, v in (metadata or {}).items()})
        try:
            writer.start(profile="ros2", library=f"ssi_bridge {__version__}")
            if info.custom_data:
                writer.add_metadata(CONFIG_METADATA_NAME, info.custom_data)
            stream.flush()
        except OSError as err:
            stream.close()
            raise RecordingError(f"cannot write bag {directory}: {err.strerror or err}") from err
        logger.info("recording to %s (%s chunks)", directory, compression or "uncompressed")
        return cls(directory, stream, writer, info, flush_period_s)

    @property
    def directory(self) -> Path:
        """Absolute path of the bag directory."""
        return self._directory

    @property
    def message_count(self) -> int:
        """Messages written so far."""
        return self._info.message_count

    @property
    def error(self) -> RecordingError | None:
        """The write error that stopped this recorder, if any."""
        return self._error

    def add_topic(self, name: str, type_name: str, qos: QoSProfile | None = None) -> None:
        """Register a topic (once) with its type ``pkg/msg/Type`` and offered QoS."""
        with self._lock:
            self._check()
            if name in self._channels:
                if self._channels[name].info.type != build_schema(type_name).name:
                    raise RecordingError(f"topic {name} already recorded with type "
                                         f"{self._channels[name].info.type}")
                return
            schema = build_schema(type_name)
            qtext = qos_text([qos or DEFAULT_QOS])
            channel_meta = {"offered_qos_profiles": qtext}
            if schema.type_hash:
                channel_meta["topic_type_hash"] = schema.type_hash
            try:
                if schema.name not in self._schemas:
                    self._schemas[schema.name] = self._writer.register_schema(
                        schema.name, "ros2msg", schema.text.encode())
                channel_id = self._writer.register_channel(
                    name, "cdr", self._schemas[schema.name], channel_meta)
            except OSError as err:
                raise self._fail(err) from err
            info = TopicInfo(name, schema.name, qtext, schema.type_hash)
            self._info.topics.append(info)
            self._channels[name] = _Channel(channel_id, info)

    def write(self, topic: str, msg: Any, log_time_ns: int,
              publish_time_ns: int | None = None) -> None:
        """Serialize ``msg`` to CDR and append it (log time = receive, publish = send time)."""
        data = cdr.serialize(msg)
        with self._lock:
            self._check()
            channel = self._channels.get(topic)
            if channel is None:
                raise RecordingError(f"topic {topic} was not added to the recorder")
            try:
                self._writer.add_message(
                    channel.channel_id, log_time_ns, data,
                    log_time_ns if publish_time_ns is None else publish_time_ns,
                    channel.sequence)
            except OSError as err:
                raise self._fail(err) from err
            channel.sequence += 1
            channel.info.message_count += 1
            info = self._info
            if info.start_ns == 0 or log_time_ns < info.start_ns:
                info.start_ns = log_time_ns
            info.end_ns = max(info.end_ns, log_time_ns)
            self._dirty = True

    def flush(self) -> None:
        """Close the open chunk and hand everything to the OS (survives a kill -9)."""
        with self._lock:
            self._check()
            if not self._dirty:
                return
            try:
                self._writer.flush()
            except OSError as err:
                raise self._fail(err) from err
            self._dirty = False

    def close(self) -> BagSummary:
        """Finish the MCAP file (summary, statistics, indexes), write metadata.yaml."""
        self._stop.set()
        if self._flusher is not threading.current_thread():
            self._flusher.join()
        with self._lock:
            if self._closed:
                raise RecordingError(f"bag {self._directory} is already closed")
            self._closed = True
            if self._error is None:
                try:
                    self._writer.add_metadata("rosbag2", {
                        "serialized_metadata": metadata_text(self._info),
                        "ROS_DISTRO": ROS_DISTRO})
                    self._writer.finish()
                    self._stream.flush()
                    os.fsync(self._stream.fileno())
                    self._stream.close()
                    write_metadata(self._directory, self._info)
                except OSError as err:
                    self._fail(err)
            if self._error is not None:
                try:
                    self._stream.close()
                except OSError:
                    logger.debug("closing %s after a write error failed too", self._directory)
                raise RecordingError(f"{self._error}; the bag was left without a summary: "
                                     f"`replay --recover {self._directory}` rebuilds it")
        info = self._info
        logger.info("closed %s: %d messages", self._directory, info.message_count)
        return BagSummary(self._directory, info.message_count, info.duration_ns / 1e9,
                          {t.name: t.message_count for t in info.topics})

    def _check(self) -> None:
        """Raise if the recorder is closed or failed (called with the lock held)."""
        if self._error is not None:
            raise self._error
        if self._closed:
            raise RecordingError(f"bag {self._directory} is closed")

    def _fail(self, err: OSError) -> RecordingError:
        """Enter the failed state after a file-system error and describe it."""
        if self._error is None:
            self._error = RecordingError(
                f"writing bag {self._directory} failed: {err.strerror or err}"
                f" (errno {err.errno}); recording stopped")
            logger.error("%s", self._error)
        return self._error

    def _flush_loop(self) -> None:
        """Flush every period so that a crash loses at most ``flush_period_s`` of data."""
        while not self._stop.wait(self._flush_period):
            try:
                self.flush()
            except (RecordingError, ValueError):
                return
            start = time.monotonic()
            try:
                os.fsync(self._stream.fileno())
            except (OSError, ValueError):
                pass
            logger.debug("fsync %.1f ms", (time.monotonic() - start) * 1e3)
