"""Rebuild a bag left without summary or metadata.yaml (kill -9, power loss, disk full).

The recorder closes a chunk and flushes the file every half second, so everything before the
last flush is a sequence of complete MCAP records. Recovery reads records sequentially up to
the first incomplete or corrupt one, then rewrites the file with the same schemas, channels
and messages plus chunk indexes, message indexes, statistics and summary, and writes
metadata.yaml. The original file is replaced only after the new one and metadata.yaml are
complete; a write error (disk full) removes the partial files and leaves the bag as it was
(RecordingError).
Documented command: ``ros2 run ssi_bridge replay --recover DIR``.
"""

from __future__ import annotations

import logging
import os
import struct
import zlib
from pathlib import Path

from mcap.exceptions import McapError
from mcap.records import Channel, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record.bag import BagSummary
from ssi_bridge.record.metadata import (
    METADATA_FILE,
    ROS_DISTRO,
    BagInfo,
    TopicInfo,
    metadata_text,
)

logger = logging.getLogger(__name__)


def _mcap_file(directory: Path) -> Path:
    """The single ``*.mcap`` file of a bag directory."""
    files = sorted(directory.glob("*.mcap"))
    if len(files) != 1:
        raise RecordingError(f"{directory}: expected one .mcap file, found {len(files)}")
    return files[0]


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
    """Rewrite the MCAP file of ``directory`` with a summary and write metadata.yaml."""
    directory = Path(directory).absolute()
    if not directory.is_dir():
        raise RecordingError(f"{directory} is not a bag directory")
    source = _mcap_file(directory)
    if source.read_bytes()[:8] != b"\x89MCAP0\r\n":
        raise RecordingError(f"{source} is not an MCAP file (bad magic)")
    schemas, channels, messages, metadata, complete = _salvage(source)
    if not channels:
        raise RecordingError(f"{source}: no channel record survived; nothing to recover")
    messages.sort(key=lambda m: m.log_time)
    tmp = source.with_name(source.name + ".recovering")
    meta_tmp = directory / f".{METADATA_FILE}.recovering"
    kind = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}.get(
        compression, CompressionType.NONE)
    topics = {c.id: TopicInfo(c.topic, next((s.name for s in schemas if s.id == c.schema_id), ""),
                              c.metadata.get("offered_qos_profiles", ""),
                              c.metadata.get("topic_type_hash", "")) for c in channels}
    info = BagInfo(source.name, list(topics.values()))
    try:
        _write(tmp, kind, schemas, channels, messages, metadata, topics, info)
        with open(meta_tmp, "w", encoding="utf-8") as meta:
            meta.write(metadata_text(info))
            meta.flush()
            os.fsync(meta.fileno())
    except OSError as err:
        # a full disk: leave nothing behind (no 0-byte .recovering), the bag as it was
        for leftover in (tmp, meta_tmp):
            leftover.unlink(missing_ok=True)
        raise RecordingError(
            f"{directory}: writing the recovered bag failed: {err.strerror or err}"
            f" (errno {err.errno}); nothing was changed, the bag is as it was") from err
    os.replace(tmp, source)
    os.replace(meta_tmp, directory / METADATA_FILE)
    logger.info("recovered %s: %d messages (%s)", directory, info.message_count,
                "file was complete" if complete else "file was truncated")
    return BagSummary(directory, info.message_count, info.duration_ns / 1e9,
                      {t.name: t.message_count for t in info.topics})


def _write(tmp: Path, kind: CompressionType, schemas: list[Schema], channels: list[Channel],
           messages: list[Message], metadata: list[Metadata], topics: dict[int, TopicInfo],
           info: BagInfo) -> None:
    """Write the rebuilt MCAP file to ``tmp`` (fsync'd); OSError on a write error."""
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
            topics[msg.channel_id].message_count += 1
        if messages:
            info.start_ns, info.end_ns = messages[0].log_time, messages[-1].log_time
        writer.add_metadata("rosbag2", {"serialized_metadata": metadata_text(info),
                                        "ROS_DISTRO": ROS_DISTRO})
        writer.finish()
        out.flush()
        os.fsync(out.fileno())
