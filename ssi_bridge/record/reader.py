"""Open a recorded session (ours or rosbag2's, one file or split) for replay and plotting.

Accepts a bag directory (``metadata.yaml`` naming its files) or a bare ``.mcap`` file, and
turns every way of being unreadable into a :class:`RecordingError` that says what is wrong:
missing path, a directory without metadata.yaml or MCAP file, a storage other than mcap, a
file that is not MCAP at all (foreign), a truncated file (no summary: run ``--recover``).
"""

from __future__ import annotations

import heapq
import logging
from collections.abc import Generator, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

from mcap.exceptions import McapError
from mcap.reader import McapReader, make_reader
from mcap.records import Message
from mcap.summary import Summary

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record.metadata import METADATA_FILE, file_index, read_metadata

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
    #: the schema stored in the bag (``ros2msg`` text with its dependencies), for viewers
    schema_data: bytes = b""
    schema_encoding: str = ""


def find_mcaps(path: Path) -> list[Path]:
    """The MCAP files of ``path`` (a bag directory or an ``.mcap`` file), checked to exist.

    A bag directory's files come from metadata.yaml's ``relative_file_paths`` (several for a
    split session); without metadata.yaml (a session cut by a crash and not recovered yet) its
    ``<name>_<k>.mcap`` files in index order.

    :raises RecordingError: no such path, a bad or unsupported metadata.yaml, files it names
        that are missing, or no MCAP file at all
    """
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such bag directory or file")
    if path.is_file():
        return [path]
    meta = path / METADATA_FILE
    if meta.is_file():
        try:
            info = read_metadata(path)
        except (OSError, ValueError) as err:
            raise RecordingError(f"{meta}: not a rosbag2 metadata file ({err})") from err
        storage = info.get("storage_identifier", "")
        if storage != "mcap":
            raise RecordingError(f"{path}: storage {storage!r} is not supported, only 'mcap'")
        files = [path / f for f in info.get("relative_file_paths") or []]
        if not files:
            raise RecordingError(f"{meta}: relative_file_paths is empty")
        missing = [f.name for f in files if not f.is_file()]
        if missing:
            raise RecordingError(f"{path}: {', '.join(missing)} named in metadata.yaml "
                                 f"{'is' if len(missing) == 1 else 'are'} missing")
        return files
    found = bag_files(path)
    if not found:
        raise RecordingError(f"{path}: neither metadata.yaml nor an .mcap file in it")
    logger.warning("%s: no metadata.yaml; reading %s", path, ", ".join(f.name for f in found))
    return found


def bag_files(directory: Path) -> list[Path]:
    """The ``*.mcap`` files of a directory, ``<dirname>_<k>.mcap`` in the order of k first."""
    found = sorted(directory.glob("*.mcap"))
    numbered = {f: file_index(directory.name, f.name) for f in found}
    return sorted(found, key=lambda f: (numbered[f] is None, numbered[f] or 0, f.name))


def read_summary(stream: BinaryIO, path: Path) -> tuple[McapReader, Summary]:
    """Check the magic, footer and summary of one MCAP file; RecordingError says what is
    wrong (foreign, truncated: run ``--recover``, damaged).

    :param stream: the file, open for binary reading
    :param path: its path (for the messages)
    """
    stream.seek(0)
    head = stream.read(8)
    if head != MCAP_MAGIC:
        raise RecordingError(f"{path}: not an MCAP file (starts with {head[:8]!r})")
    size = path.stat().st_size
    stream.seek(max(0, size - 8))
    if size < 16 or stream.read(8) != MCAP_MAGIC:
        raise RecordingError(f"{path}: truncated MCAP file (no footer); recover it with"
                             f" `replay --recover {path.parent}`")
    stream.seek(0)
    reader = make_reader(stream)
    try:
        summary = reader.get_summary()
        header = reader.get_header()
    except (McapError, EOFError, ValueError) as err:
        raise RecordingError(f"{path}: damaged MCAP file ({err})") from err
    if summary is None or summary.statistics is None:
        raise RecordingError(f"{path}: MCAP file without summary; recover it with "
                             f"`replay --recover {path.parent}`")
    if header.profile != "ros2":
        logger.warning("%s: profile %r, expected 'ros2'", path, header.profile)
    return reader, summary


@dataclass
class _Part:
    """One file of a bag holding messages, and their log-time span."""

    path: Path
    start_ns: int
    end_ns: int


class Bag:
    """A summarised MCAP bag of one or more files (use as a context manager).

    Every file's summary is checked on opening; the topics are the union of the files' (the
    counts summed), the span from the first message of any file to the last. Messages come
    in log-time order across files, with at most the files whose spans overlap open at once.

    :param path: a bag directory or one MCAP file
    :raises RecordingError: no MCAP file there, or one without a readable summary
        (``replay --recover`` rebuilds it)
    """

    def __init__(self, path: Path) -> None:
        self.source = Path(path)
        self.files = find_mcaps(path)
        #: the bag as given: its directory, or the bare file
        self.path = self.source if self.source.is_dir() else self.files[0]
        self.topics: dict[str, RecordedTopic] = {}
        self._parts: list[_Part] = []
        for file in self.files:
            with open(file, "rb") as stream:
                _reader, summary = read_summary(stream, file)
                self._add(file, summary)
        spans = [p for p in self._parts if p.end_ns >= p.start_ns > 0]
        self.start_ns = min((p.start_ns for p in spans), default=0)
        self.end_ns = max((p.end_ns for p in spans), default=0)
        self._open: list[BinaryIO] = []

    def _add(self, file: Path, summary: Summary) -> None:
        """Merge one file's channels and statistics into the bag's topics."""
        stats = summary.statistics
        assert stats is not None
        counts = stats.channel_message_counts
        for cid, ch in summary.channels.items():
            schema = summary.schemas.get(ch.schema_id)
            if ch.message_encoding != "cdr" or schema is None:
                logger.warning("%s: topic %s is not ROS 2 CDR; skipped", file, ch.topic)
                continue
            known = self.topics.get(ch.topic)
            if known is not None and known.type != schema.name:
                raise RecordingError(f"{file}: topic {ch.topic} has type {schema.name}, an "
                                     f"earlier file of the bag {known.type}")
            count = counts.get(cid, 0) + (known.message_count if known else 0)
            self.topics[ch.topic] = RecordedTopic(
                ch.topic, schema.name,
                known.qos_text if known else ch.metadata.get("offered_qos_profiles", ""), count,
                schema.data, schema.encoding)
        if stats.message_count:
            self._parts.append(_Part(file, stats.message_start_time, stats.message_end_time))

    def messages(self, topics: Iterable[str] | None = None, start_ns: int | None = None,
                 ) -> Generator[tuple[str, Message], None, None]:
        """Yield ``(topic, record)`` in log-time order, optionally filtered.

        :param topics: the topics to read (default: all)
        :param start_ns: skip messages logged before this time (ns)
        """
        wanted = list(topics) if topics is not None else list(self.topics)
        parts = sorted((p for p in self._parts if start_ns is None or p.end_ns >= start_ns),
                       key=lambda p: p.start_ns)
        heap: list[tuple[int, int, str, Message, Iterator[tuple[str, Message]]]] = []
        serial = 0      # ties keep file order, then order within the file
        while parts or heap:
            # open the next file as soon as its first message could come before the heap's
            while parts and (not heap or parts[0].start_ns <= heap[0][0]):
                part = parts.pop(0)
                it = self._file_messages(part.path, wanted, start_ns)
                for topic, record in it:
                    heapq.heappush(heap, (record.log_time, serial, topic, record, it))
                    serial += 1
                    break
            if not heap:
                continue
            _t, _s, topic, record, it = heapq.heappop(heap)
            yield topic, record
            for nxt_topic, nxt in it:
                heapq.heappush(heap, (nxt.log_time, serial, nxt_topic, nxt, it))
                serial += 1
                break

    def _file_messages(self, path: Path, topics: list[str], start_ns: int | None,
                       ) -> Iterator[tuple[str, Message]]:
        """One file's messages in log-time order; the file is closed when they run out."""
        with open(path, "rb") as stream:
            self._open.append(stream)
            try:
                reader = make_reader(stream)
                for _schema, channel, message in reader.iter_messages(
                        topics=topics, starting_at=start_ns, log_time_order=True):
                    yield channel.topic, message
            except (McapError, EOFError, ValueError) as err:
                raise RecordingError(f"{path}: damaged chunk ({err})") from err
            finally:
                if stream in self._open:
                    self._open.remove(stream)

    def decoded(self, topics: Iterable[str] | None = None,
                ) -> Iterator[tuple[str, int, object]]:
        """Yield ``(topic, log_time_ns, message)`` deserialized with rclpy.

        :param topics: the topics to read (default: all)
        :raises RecordingError: a topic's message type is not installed
        """
        from rclpy.serialization import deserialize_message

        from ssi_bridge.record.types import message_class
        classes = {t: message_class(self.topics[t].type) for t in (topics or self.topics)}
        for topic, record in self.messages(classes):
            yield topic, record.log_time, deserialize_message(record.data, classes[topic])

    def close(self) -> None:
        """Close the files a message iteration left open."""
        for stream in list(self._open):
            stream.close()
        self._open.clear()

    def __enter__(self) -> Bag:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
