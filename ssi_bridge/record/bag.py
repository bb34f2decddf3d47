"""Record rclpy messages into a rosbag2-compatible MCAP bag directory, split as rosbag2 does.

Layout as rosbag2 (storage plugin ``mcap``) writes it: ``<dir>/<dirname>_0.mcap`` with
profile ``ros2``, one ``ros2msg`` schema per type, ``cdr`` channels carrying
``offered_qos_profiles`` and ``topic_type_hash``, zstd/lz4 chunks with message indexes and a
summary with statistics, a ``rosbag2`` metadata record; and ``<dir>/metadata.yaml``.

Splitting (``max_size`` bytes, ``max_duration_s``; 0 = never) follows rosbag2's rule
(``record/split.py``): the message that splits opens ``<dirname>_<k+1>.mcap``. A closed file
is a complete MCAP (summary, chunk index, statistics) that starts with the configuration
metadata record and every schema and channel, so each file stands alone; the per-chunk
index lives with the open file only, so a session's memory does not grow with its length.

Log times never decrease in a bag (``mcap doctor --strict-message-order``; a reader in file
order sees time order): a message handed over with a log time before the latest one written
(its thread was preempted between reading the clock and writing, or the clock stepped back) is
written at that latest log time; its publish time stays as given.

Crash safety: a background thread closes the open chunk and flushes the file every
``flush_period_s`` (0.5 s), so a kill -9 loses at most that much; ``recover.recover_bag``
rebuilds the cut last file and metadata.yaml. Any OSError (disk full, EFBIG, EIO) turns the
recorder into a failed state and surfaces as :class:`RecordingError` on the next call, so the
node can stop recording and report ERROR while it keeps publishing.
"""

from __future__ import annotations

import logging
import os
import shutil
import threading
import time
from pathlib import Path
from typing import Any

from rclpy.qos import QoSProfile

from ssi_bridge import __version__
from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record import cdr
from ssi_bridge.record.heap import release_free_memory
from ssi_bridge.record.mcap_file import Channel, McapFile
from ssi_bridge.record.mcap_write import ChunkBuffers
from ssi_bridge.record.metadata import (
    ROS_DISTRO,
    BagInfo,
    BagSummary,
    FileInfo,
    TopicInfo,
    file_name,
    metadata_text,
    write_metadata,
)
from ssi_bridge.record.qos import qos_text
from ssi_bridge.record.schema import build_schema
from ssi_bridge.record.session import create_bag_directory
from ssi_bridge.record.split import MIN_SPLIT_SIZE, SplitPolicy

__all__ = ["CONFIG_METADATA_NAME", "MIN_SPLIT_SIZE", "BagRecorder", "BagSummary", "SplitPolicy"]

logger = logging.getLogger(__name__)

#: the node's compression names -> the Chunk record's
COMPRESSIONS = {"zstd": "zstd", "lz4": "lz4", "none": "", "": ""}
#: default QoS of a topic added without one (rclpy's default publisher profile)
DEFAULT_QOS = QoSProfile(depth=10)
#: name of the MCAP metadata record holding the session configuration
CONFIG_METADATA_NAME = "ssi_bridge"


class BagRecorder:
    """Write one bag; thread-safe ``write`` from any thread (e.g. the node's 1 kHz timer).

    Made by :meth:`open` (``directory``, ``info``, ``compression``, ``chunk_size``, ``split``
    and ``flush_period_s`` as it checked them).
    """

    def __init__(self, directory: Path, info: BagInfo, compression: str,
                 chunk_size: int, split: SplitPolicy, flush_period_s: float) -> None:
        self._directory = directory
        self._info = info
        #: the open chunk's buffers, kept for the whole session
        self._chunks = ChunkBuffers(compression)
        self._chunk_size = chunk_size
        self._split = split
        self._lock = threading.Lock()
        self._topics: dict[str, Channel] = {}
        self._file: McapFile | None = None
        #: finished files whose fsync + close the flush thread still owes
        self._closing: list[McapFile] = []
        self._dirty = False
        self._error: RecordingError | None = None
        self._closed = False
        self._stop = threading.Event()
        self._flush_period = flush_period_s
        self._flusher = threading.Thread(target=self._flush_loop, name="bag-flush", daemon=True)

    @classmethod
    def open(cls, directory: Path, *, compression: str = "zstd",
             metadata: dict[str, str] | None = None, flush_period_s: float = 0.5,
             chunk_size: int = 1024 * 1024, max_size: int = 0,
             max_duration_s: float = 0.0) -> BagRecorder:
        """Create the bag directory and its first MCAP file; refuse an existing or unwritable
        one, an unknown compression and split limits below the minimum.

        :param directory: the new bag directory (must not exist)
        :param compression: "zstd", "lz4", "none" or ""
        :param metadata: the session configuration, stored as an MCAP metadata record
        :param flush_period_s: how often data is handed to the OS (s)
        :param chunk_size: bytes of an MCAP chunk
        :param max_size: split after this many bytes, ``max_duration_s`` s per file (0: never)
        :raises RecordingError: any of the refusals above, or an OS error creating the files
        """
        directory = Path(directory).absolute()
        if compression not in COMPRESSIONS:
            raise RecordingError(f"compression {compression!r}: expected zstd, lz4 or none")
        split = SplitPolicy(max_size, max_duration_s)
        create_bag_directory(directory)
        info = BagInfo(custom_data={str(k): str(v) for k, v in (metadata or {}).items()})
        rec = cls(directory, info, COMPRESSIONS[compression], chunk_size, split, flush_period_s)
        try:
            rec._file = rec._open_file()
        except OSError as err:
            shutil.rmtree(directory, ignore_errors=True)  # refused: nothing left on disk
            raise RecordingError(f"cannot create bag {directory}: {err.strerror or err}") from err
        rec._flusher.start()
        limits = ([f"split at {max_size} B"] if max_size else []) + (
            [f"split every {max_duration_s:g} s"] if max_duration_s else [])
        logger.info("recording to %s (%s chunks%s)", directory, compression or "uncompressed",
                    "".join(f"; {x}" for x in limits))
        return rec

    @property
    def directory(self) -> Path:
        """Absolute path of the bag directory."""
        return self._directory

    @property
    def message_count(self) -> int:
        """Messages written so far (all files)."""
        return self._info.message_count

    @property
    def files(self) -> list[str]:
        """Names of the bag's MCAP files so far, the open one last."""
        return [f.path for f in self._info.files]

    @property
    def error(self) -> RecordingError | None:
        """The write error that stopped this recorder, if any."""
        return self._error

    def add_topic(self, name: str, type_name: str, qos: QoSProfile | None = None) -> None:
        """Register a topic (once) with its type ``pkg/msg/Type`` and offered QoS.

        :param name: the topic's name
        :param type_name: its type ``pkg/msg/Type``
        :param qos: its offered QoS (default: rclpy's default publisher profile)
        :raises RecordingError: bag closed or failed, topic known with another type, type absent
        """
        with self._lock:
            self._check()
            schema = build_schema(type_name)
            if name in self._topics:
                if self._topics[name].info.type != schema.name:
                    raise RecordingError(f"topic {name} already recorded with type "
                                         f"{self._topics[name].info.type}")
                return
            qtext = qos_text([qos or DEFAULT_QOS])
            channel_meta = {"offered_qos_profiles": qtext}
            if schema.type_hash:
                channel_meta["topic_type_hash"] = schema.type_hash
            topic = Channel(TopicInfo(name, schema.name, qtext, schema.type_hash),
                           schema.text.encode(), channel_meta)
            assert self._file is not None
            try:
                self._file.add_channel(name, schema.name, topic.schema_text, channel_meta)
            except OSError as err:
                raise self._fail(err) from err
            self._info.topics.append(topic.info)
            self._topics[name] = topic

    def write(self, topic: str, msg: object, log_time_ns: int,
              publish_time_ns: int | None = None) -> None:
        """Serialize ``msg`` (an rclpy message of the topic's type) to CDR and append it:
        ``topic``, ``log_time_ns``, ``publish_time_ns`` and errors as :meth:`write_serialized`.
        """
        self.write_serialized(topic, cdr.serialize(msg), log_time_ns, publish_time_ns)

    def write_serialized(self, topic: str, data: bytes, log_time_ns: int,
                         publish_time_ns: int | None = None) -> None:
        """Append a message already serialized to CDR (a snapshot's ring holds such), at
        ``log_time_ns`` or the latest log time written if that is later.

        :param topic: a topic added with :meth:`add_topic`
        :param data: the CDR bytes
        :param log_time_ns: when it was received (ns)
        :param publish_time_ns: when it was sent (ns; default: ``log_time_ns``)
        :raises RecordingError: the topic is unknown, or the bag is closed or failed
        """
        with self._lock:
            self._check()
            entry = self._topics.get(topic)
            if entry is None:
                raise RecordingError(f"topic {topic} was not added to the recorder")
            file = self._file
            assert file is not None
            log_time_ns = max(log_time_ns, self._info.end_ns)  # never before the latest
            try:
                if self._split.due(file.info, file.size, log_time_ns):
                    file = self._next_file()
                file.write(topic, log_time_ns, data,
                           log_time_ns if publish_time_ns is None else publish_time_ns,
                           entry.sequence)
            except OSError as err:
                raise self._fail(err) from err
            entry.sequence += 1
            entry.info.message_count += 1
            info = self._info
            if info.start_ns == 0 or log_time_ns < info.start_ns:
                info.start_ns = log_time_ns
            info.end_ns = max(info.end_ns, log_time_ns)
            self._dirty = True

    def split(self) -> str:
        """Finish the open file now and start the next ``<name>_<k+1>.mcap`` (rosbag2's
        ``~/split_bagfile``); returns the new file's name. Raises RecordingError when the open
        file holds no message yet (every file of a bag holds at least one), or when a
        file-system error fails the bag (the same error on every later call).
        """
        with self._lock:
            self._check()
            assert self._file is not None
            if self._file.info.message_count == 0:
                raise RecordingError(f"{self._file.info.path} holds no message yet; "
                                     "nothing to split")
            try:
                return self._next_file().info.path
            except OSError as err:
                raise self._fail(err) from err

    def flush(self) -> None:
        """Close the open chunk and hand everything to the OS (survives a kill -9).

        :raises RecordingError: a file-system error (the bag is failed from then on)
        """
        with self._lock:
            self._check()
            if not self._dirty:
                return
            assert self._file is not None
            try:
                self._file.flush()
            except OSError as err:
                raise self._fail(err) from err
            self._dirty = False

    def close(self) -> BagSummary:
        """Finish the open MCAP file (summary, statistics, indexes), write metadata.yaml.

        :returns: what was written (directory, files, message count, span)
        :raises RecordingError: closed twice, or a file-system error left the bag without a
            summary (``replay --recover`` rebuilds it)
        """
        self._stop.set()
        if self._flusher.is_alive() and self._flusher is not threading.current_thread():
            self._flusher.join()
        with self._lock:
            if self._closed:
                raise RecordingError(f"bag {self._directory} is already closed")
            self._closed = True
            file, self._file = self._file, None
            pending, self._closing = self._closing, []
            if self._error is None:
                try:
                    assert file is not None
                    self._finish(file)
                    for done in (*pending, file):
                        done.sync_close()
                    write_metadata(self._directory, self._info)
                except OSError as err:
                    self._fail(err)
            if self._error is not None:
                for left in (*pending, file):
                    if left is not None:
                        left.abandon()
                raise RecordingError(f"{self._error}; the bag was left without a summary: "
                                     f"`replay --recover {self._directory}` rebuilds it")
        release_free_memory()  # the session's writer and buffers (record/heap.py)
        info = self._info
        logger.info("closed %s: %d messages in %d file(s)", self._directory,
                    info.message_count, len(info.files))
        return BagSummary(self._directory, info.message_count, info.duration_ns / 1e9,
                          {t.name: t.message_count for t in info.topics},
                          tuple(f.path for f in info.files))

    # -- files ---------------------------------------------------------------------------------
    def _open_file(self) -> McapFile:
        """Start the next ``<name>_<k>.mcap`` (:meth:`McapFile.start`); a split that could
        not start it (disk full) leaves no header without messages beside the closed files."""
        entry = FileInfo(file_name(self._directory.name, len(self._info.files)))
        file = McapFile.start(self._directory / entry.path, entry, self._chunks,
                              self._chunk_size, f"ssi_bridge {__version__}",
                              self._info.custom_data, CONFIG_METADATA_NAME, self._topics,
                              remove_on_failure=bool(self._info.files))
        self._info.files.append(entry)
        return file

    def _finish(self, file: McapFile) -> None:
        """Write the rosbag2 metadata record (the bag as known now) and the file's summary."""
        file.add_metadata("rosbag2", {"serialized_metadata": metadata_text(self._info),
                                      "ROS_DISTRO": ROS_DISTRO})
        file.finish()

    def _next_file(self) -> McapFile:
        """Split: finish the open file now, leave its fsync to the flush thread, open the next.

        Called with the lock held on the writing thread; the finish costs one chunk's
        compression and the summary, the fsync (which may wait on the disk) is not done here.
        """
        assert self._file is not None
        old = self._file
        self._finish(old)
        self._closing.append(old)
        self._file = self._open_file()
        logger.info("%s: closed %s (%d messages), writing %s", self._directory, old.info.path,
                    old.info.message_count, self._file.info.path)
        return self._file

    # -- state ---------------------------------------------------------------------------------
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
        """Flush every period so that a crash loses at most ``flush_period_s`` of data; fsync
        and close the files a split finished."""
        while not self._stop.wait(self._flush_period):
            try:
                self.flush()
            except (RecordingError, ValueError):
                return
            with self._lock:
                current = self._file
                pending, self._closing = self._closing, []
            start = time.monotonic()
            for done in pending:
                try:
                    done.sync_close()
                except OSError as err:
                    with self._lock:
                        self._fail(err)
                    return
            if pending:
                release_free_memory()  # what the split freed (record/heap.py)
            try:
                if current is not None:
                    os.fsync(current.fileno())
            except (OSError, ValueError):
                pass
            logger.debug("fsync %.1f ms", (time.monotonic() - start) * 1e3)

