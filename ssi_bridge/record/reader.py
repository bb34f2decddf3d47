"""Open a recorded session (ours or rosbag2's) for replay and plotting.

Accepts a bag directory (``metadata.yaml`` naming the file) or a bare ``.mcap`` file, and
turns every way of being unreadable into a :class:`RecordingError` that says what is wrong:
missing path, a directory without metadata.yaml or MCAP file, a storage other than mcap, a
file that is not MCAP at all (foreign), a truncated file (no summary: run ``--recover``).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

from mcap.exceptions import McapError
from mcap.reader import McapReader, make_reader
from mcap.records import Message

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record.metadata import METADATA_FILE, read_metadata

logger = logging.getLogger(__name__)

MCAP_MAGIC = b"\x89MCAP0\r\n"


@dataclass(frozen=True)
class RecordedTopic:
    """One recorded topic as the bag describes it."""

    name: str
    #: ``pkg/msg/Type``
    type: str
    #: ``offered_qos_profiles`` text of the channel ("" when absent)
    qos_text: str
    message_count: int


def find_mcap(path: Path) -> Path:
    """The MCAP file of ``path`` (a bag directory or an ``.mcap`` file), checked to exist."""
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such bag directory or file")
    if path.is_file():
        return path
    meta = path / METADATA_FILE
    if meta.is_file():
        try:
            info = read_metadata(path)
        except (OSError, ValueError) as err:
            raise RecordingError(f"{meta}: not a rosbag2 metadata file ({err})") from err
        storage = info.get("storage_identifier", "")
        if storage != "mcap":
            raise RecordingError(f"{path}: storage {storage!r} is not supported, only 'mcap'")
        files = [path / f for f in info.get("relative_file_paths", [])]
        if not files:
            raise RecordingError(f"{meta}: relative_file_paths is empty")
        if len(files) > 1:
            logger.warning("%s: split bag, reading only %s", path, files[0].name)
        if not files[0].is_file():
            raise RecordingError(f"{path}: {files[0].name} named in metadata.yaml is missing")
        return files[0]
    found = sorted(path.glob("*.mcap"))
    if not found:
        raise RecordingError(f"{path}: neither metadata.yaml nor an .mcap file in it")
    logger.warning("%s: no metadata.yaml; reading %s", path, found[0].name)
    return found[0]


class Bag:
    """A seekable, summarised MCAP bag (use as a context manager)."""

    def __init__(self, path: Path) -> None:
        self.path = find_mcap(path)
        self._stream: BinaryIO = open(self.path, "rb")  # noqa: SIM115 - closed in close()
        try:
            self._reader, self.topics, self.start_ns, self.end_ns = self._load()
        except BaseException:
            self._stream.close()
            raise

    def _load(self) -> tuple[McapReader, dict[str, RecordedTopic], int, int]:
        """Check the magic and the summary; collect topics and the time span."""
        head = self._stream.read(8)
        if head != MCAP_MAGIC:
            raise RecordingError(f"{self.path}: not an MCAP file (starts with {head[:8]!r})")
        size = self.path.stat().st_size
        self._stream.seek(max(0, size - 8))
        if size < 16 or self._stream.read(8) != MCAP_MAGIC:
            raise RecordingError(f"{self.path}: truncated MCAP file (no footer); recover it with"
                                 f" `replay --recover {self.path.parent}`")
        self._stream.seek(0)
        reader = make_reader(self._stream)
        try:
            summary = reader.get_summary()
            header = reader.get_header()
        except (McapError, EOFError, ValueError) as err:
            raise RecordingError(f"{self.path}: damaged MCAP file ({err})") from err
        if summary is None or summary.statistics is None:
            raise RecordingError(f"{self.path}: MCAP file without summary; recover it with "
                                 f"`replay --recover {self.path.parent}`")
        if header.profile != "ros2":
            logger.warning("%s: profile %r, expected 'ros2'", self.path, header.profile)
        counts = summary.statistics.channel_message_counts
        topics = {}
        for cid, ch in summary.channels.items():
            schema = summary.schemas.get(ch.schema_id)
            if ch.message_encoding != "cdr" or schema is None:
                logger.warning("%s: topic %s is not ROS 2 CDR; skipped", self.path, ch.topic)
                continue
            topics[ch.topic] = RecordedTopic(ch.topic, schema.name,
                                             ch.metadata.get("offered_qos_profiles", ""),
                                             counts.get(cid, 0))
        stats = summary.statistics
        return reader, topics, stats.message_start_time, stats.message_end_time

    def messages(self, topics: Iterable[str] | None = None, start_ns: int | None = None,
                 ) -> Iterator[tuple[str, Message]]:
        """Yield ``(topic, record)`` in log-time order, optionally filtered."""
        wanted = list(topics) if topics is not None else list(self.topics)
        try:
            for _schema, channel, message in self._reader.iter_messages(
                    topics=wanted, start_time=start_ns, log_time_order=True):
                yield channel.topic, message
        except (McapError, EOFError, ValueError) as err:
            raise RecordingError(f"{self.path}: damaged chunk ({err})") from err

    def decoded(self, topics: Iterable[str] | None = None) -> Iterator[tuple[str, int, Any]]:
        """Yield ``(topic, log_time_ns, message)`` deserialized with rclpy."""
        from rclpy.serialization import deserialize_message

        from ssi_bridge.record.types import message_class
        classes = {t: message_class(self.topics[t].type) for t in (topics or self.topics)}
        for topic, record in self.messages(classes):
            yield topic, record.log_time, deserialize_message(record.data, classes[topic])

    def close(self) -> None:
        """Close the file."""
        self._stream.close()

    def __enter__(self) -> Bag:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
