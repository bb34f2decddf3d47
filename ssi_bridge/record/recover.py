"""Rebuild a bag left without summary or metadata.yaml (kill -9, power loss, disk full).

The recorder closes a chunk and flushes the file every half second, so everything before the
last flush is a sequence of complete MCAP records. Recovery reads records sequentially up to
the first incomplete or corrupt one, then rewrites the file with the same schemas, channels
and messages plus chunk indexes, message indexes, statistics and summary, and writes
metadata.yaml. Of a split session only the cut file (the one open at the crash) is rewritten;
the files closed before are complete MCAP files and are only read. The cut file is replaced
only after its new copy and metadata.yaml are both complete; a write error (disk full) removes
the partial files and leaves the bag as it was (RecordingError).
Documented command: ``ros2 run ssi_bridge replay --recover DIR``.
"""

from __future__ import annotations

import logging
import os
import struct
import zlib
from pathlib import Path
from typing import BinaryIO

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.summary import Summary
from mcap.writer import CompressionType, Writer

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record.metadata import (
    METADATA_FILE,
    ROS_DISTRO,
    BagInfo,
    BagSummary,
    FileInfo,
    TopicInfo,
    metadata_text,
)
from ssi_bridge.record.reader import MCAP_MAGIC, bag_files, read_summary

logger = logging.getLogger(__name__)


def _mcap_files(directory: Path) -> list[Path]:
    """The ``*.mcap`` files of a bag directory, a split session's in index order."""
    files = bag_files(directory)
    if not files:
        raise RecordingError(f"{directory}: expected one .mcap file, found 0")
    return files


def _salvage(path: Path) -> tuple[list[Schema], list[Channel], list[Message], list[Metadata],
                                  bool]:
    """Read every complete record of ``path``; return them and whether the file was whole."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    messages: list[Message] = []
    metadata: list[Metadata] = []
    complete = False
    with open(path, "rb") as stream:
        try:
            for record in StreamReader(stream, validate_crcs=True).records:
                if isinstance(record, Schema):
                    schemas.setdefault(record.id, record)
                elif isinstance(record, Channel):
                    channels.setdefault(record.id, record)
                elif isinstance(record, Message):
                    messages.append(record)
                elif isinstance(record, Metadata) and record.name != "rosbag2":
                    metadata.append(record)
                elif isinstance(record, Footer):
                    complete = True
        except (McapError, EOFError, struct.error, zlib.error, ValueError, KeyError) as err:
            logger.info("%s: stopped reading at an incomplete record (%s)", path, err)
        except Exception as err:  # zstd / lz4 raise their own error types on torn chunks
            logger.info("%s: stopped reading at a torn chunk (%s: %s)", path,
                        type(err).__name__, err)
    return list(schemas.values()), list(channels.values()), messages, metadata, complete


def recover_bag(directory: Path, compression: str = "zstd") -> BagSummary:
    """Rebuild what a crash cut short in ``directory`` and write metadata.yaml.

    The files of a split session that are complete (footer and summary: every file but the
    one open at the crash) are kept as they are and only read for metadata.yaml; a cut file
    is rewritten from its complete records with indexes and summary.

    :param directory: the bag directory
    :param compression: the compression of rewritten files ("zstd", "lz4", "none")
    :returns: what the bag holds now
    :raises RecordingError: not a bag directory, a file that is no MCAP file, or one of which
        no channel record survived (the bag is left unchanged)
    """
    directory = Path(directory).absolute()
    if not directory.is_dir():
        raise RecordingError(f"{directory} is not a bag directory")
    files = _mcap_files(directory)
    info = BagInfo()
    topics: dict[str, TopicInfo] = {}
    known: tuple[list[Schema], list[Channel]] = ([], [])
    rewritten: list[tuple[Path, Path]] = []  # (complete copy, the cut file it replaces)
    for source in files:
        if source == files[-1] and len(files) > 1 and source.stat().st_size < len(MCAP_MAGIC):
            # the crash came as a split created this file: it holds no record at all
            logger.warning("%s: empty, left out of the bag", source.name)
            continue
        with open(source, "rb") as stream:
            if stream.read(8) != MCAP_MAGIC:
                raise RecordingError(f"{source} is not an MCAP file (bad magic)")
            try:
                _reader, summary = read_summary(stream, source)
            except RecordingError:
                summary = None
            if summary is not None:
                entry, known = _take_complete(stream, summary, source, info, topics)
        if summary is None:
            try:
                entry, known, copy = _recover_file(source, compression, known, info, topics)
            except OSError as err:
                _discard([tmp for tmp, _ in rewritten] + [_copy_path(source)])
                raise _unchanged(directory, err) from err
            rewritten.append((copy, source))
        info.files.append(entry)
    info.topics = list(topics.values())
    spans = [f for f in info.files if f.message_count]
    if spans:
        info.start_ns = min(f.start_ns for f in spans)
        info.end_ns = max(f.end_ns for f in spans)
    meta_tmp = directory / f".{METADATA_FILE}.recovering"
    try:
        with open(meta_tmp, "w", encoding="utf-8") as meta:
            meta.write(metadata_text(info))
            meta.flush()
            os.fsync(meta.fileno())
    except OSError as err:
        _discard([tmp for tmp, _ in rewritten] + [meta_tmp])
        raise _unchanged(directory, err) from err
    for copy, source in rewritten:
        os.replace(copy, source)
    os.replace(meta_tmp, directory / METADATA_FILE)
    logger.info("recovered %s: %d messages in %d file(s), rewrote %s", directory,
                info.message_count, len(info.files),
                ", ".join(source.name for _, source in rewritten) or "none")
    return BagSummary(directory, info.message_count, info.duration_ns / 1e9,
                      {t.name: t.message_count for t in info.topics},
                      tuple(f.path for f in info.files))


def _topic(topics: dict[str, TopicInfo], channel: Channel, schemas: dict[int, Schema],
           ) -> TopicInfo:
    """The bag-wide TopicInfo of a file's channel (created on first sight)."""
    if channel.topic not in topics:
        schema = schemas.get(channel.schema_id)
        topics[channel.topic] = TopicInfo(channel.topic, schema.name if schema else "",
                                          channel.metadata.get("offered_qos_profiles", ""),
                                          channel.metadata.get("topic_type_hash", ""))
    return topics[channel.topic]


def _take_complete(stream: BinaryIO, summary: Summary, source: Path, info: BagInfo,
                   topics: dict[str, TopicInfo],
                   ) -> tuple[FileInfo, tuple[list[Schema], list[Channel]]]:
    """Account a complete file from its summary (it is not rewritten)."""
    stats = summary.statistics
    assert stats is not None
    for cid, channel in summary.channels.items():
        _topic(topics, channel, summary.schemas).message_count += \
            stats.channel_message_counts.get(cid, 0)
    entry = FileInfo(source.name)
    if stats.message_count:
        entry.add(stats.message_start_time)
        entry.add(stats.message_end_time, stats.message_count - 1)
    if not info.custom_data:
        stream.seek(0)
        for record in make_reader(stream).iter_metadata():
            if record.name != "rosbag2":
                info.custom_data.update(record.metadata)
    return entry, (list(summary.schemas.values()), list(summary.channels.values()))


def _recover_file(source: Path, compression: str,
                  known: tuple[list[Schema], list[Channel]], info: BagInfo,
                  topics: dict[str, TopicInfo],
                  ) -> tuple[FileInfo, tuple[list[Schema], list[Channel]], Path]:
    """Rebuild one cut file with a summary into a copy; return its files: entry and the copy.

    A file cut before its first chunk reached the disk has no schema or channel record;
    those of the previous file (every file registers the same topics in the same order)
    make it a valid, empty file then.
    """
    schemas, channels, messages, metadata, complete = _salvage(source)
    if not channels:
        if not known[1]:
            raise RecordingError(f"{source}: no channel record survived; nothing to recover")
        schemas, channels = known
    messages.sort(key=lambda m: m.log_time)
    tmp = _copy_path(source)
    kind = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}.get(
        compression, CompressionType.NONE)
    by_id = {s.id: s for s in schemas}
    file_topics = {c.id: _topic(topics, c, by_id) for c in channels}
    entry = FileInfo(source.name)
    with open(tmp, "wb") as out:
        writer = Writer(out, compression=kind)
        writer.start(profile="ros2", library="ssi_bridge recover")
        schema_ids = {s.id: writer.register_schema(s.name, s.encoding, s.data) for s in schemas}
        ids = {c.id: writer.register_channel(c.topic, c.message_encoding,
                                             schema_ids.get(c.schema_id, 0), dict(c.metadata))
               for c in channels}
        for record in metadata:
            writer.add_metadata(record.name, dict(record.metadata))
            info.custom_data.update(record.metadata)
        for msg in messages:
            if msg.channel_id not in ids:
                continue
            writer.add_message(ids[msg.channel_id], msg.log_time, msg.data, msg.publish_time,
                               msg.sequence)
            file_topics[msg.channel_id].message_count += 1
            entry.add(msg.log_time)
        info.topics = list(topics.values())
        writer.add_metadata("rosbag2", {"serialized_metadata": metadata_text(info),
                                        "ROS_DISTRO": ROS_DISTRO})
        writer.finish()
        out.flush()
        os.fsync(out.fileno())
    logger.info("%s: rewrote %d messages (%s)", source.name, entry.message_count,
                "file was complete" if complete else "file was truncated")
    return entry, (schemas, channels), tmp


def _copy_path(source: Path) -> Path:
    """Where the rebuilt copy of a cut file is written before it replaces the file."""
    return source.with_name(source.name + ".recovering")


def _discard(paths: list[Path]) -> None:
    """Remove partial files of a recovery that could not complete."""
    for path in paths:
        path.unlink(missing_ok=True)


def _unchanged(directory: Path, err: OSError) -> RecordingError:
    """The error of a recovery that failed to write (e.g. disk full): nothing was changed."""
    return RecordingError(
        f"{directory}: writing the recovered bag failed: {err.strerror or err}"
        f" (errno {err.errno}); nothing was changed, the bag is as it was")
