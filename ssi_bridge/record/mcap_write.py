"""MCAP records for the bag writer, built in buffers that a session keeps (MCAP spec, v0).

Why not ``mcap.writer.Writer``: it builds every chunk in a fresh ``BytesIO`` grown by realloc
on the writing thread, copies it out, compresses it with a new zstd context and frees it all,
twice a second, and keeps a Python object per chunk for the summary. In a recording node
those short-lived blocks of a few hundred kB, freed on other threads and among long-lived
ones, left glibc's heap with free memory it could not give back and the RSS grew with every
split (docs/recording.md, "Memory over hours"). Here the open chunk's records and its message
indexes are written with ``struct.pack_into`` into :class:`ChunkBuffers`, which grow to the
size a chunk needs and are then reused for every chunk of every file of the session, and the
chunk index is packed bytes, not objects. What is left per chunk is the compressor's work
space and the compressed bytes, freed as soon as the chunk is written: with the node's fixed
mmap threshold (``record/heap.py``) both are mappings of their own that leave nothing
behind.

Record layouts (little endian; opcode u8, record length u64, then the fields) follow
https://mcap.dev/spec; files are read back by the ``mcap`` reader and ``rosbags`` in tests.
"""

from __future__ import annotations

import struct
import zlib
from typing import Any, BinaryIO

import lz4.frame
import zstandard

MAGIC = b"\x89MCAP0\r\n"

OP_HEADER = 0x01
OP_FOOTER = 0x02
OP_SCHEMA = 0x03
OP_CHANNEL = 0x04
OP_MESSAGE = 0x05
OP_CHUNK = 0x06
OP_MESSAGE_INDEX = 0x07
OP_CHUNK_INDEX = 0x08
OP_STATISTICS = 0x0B
OP_METADATA = 0x0C
OP_METADATA_INDEX = 0x0D
OP_SUMMARY_OFFSET = 0x0E
OP_DATA_END = 0x0F

#: opcode, length, channel id, sequence, log time, publish time
_MESSAGE = struct.Struct("<BQHIQQ")
#: log time, offset of the message in the chunk's records
_INDEX_ENTRY = struct.Struct("<QQ")
#: opcode, length, channel id, byte length of the entries
_INDEX_HEAD = struct.Struct("<BQHI")
#: opcode, length, start time, end time, uncompressed size, uncompressed crc
_CHUNK_HEAD = struct.Struct("<BQQQQI")
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_RECORD_HEAD = struct.Struct("<BQ")
_FOOTER_FIELDS = struct.Struct("<BQQQ")

#: the chunk buffer's first size; it doubles (rarely: a session reaches its size in the
#: first chunk) up to what one chunk needs
INITIAL_CAPACITY = 64 * 1024


def _string(text: str) -> bytes:
    raw = text.encode()
    return _U32.pack(len(raw)) + raw


def _string_map(items: dict[str, str]) -> bytes:
    body = b"".join(_string(k) + _string(v) for k, v in items.items())
    return _U32.pack(len(body)) + body


def record(opcode: int, *fields: bytes) -> bytes:
    """One record: opcode, length and the already encoded ``fields``, in one allocation."""
    length = sum(len(f) for f in fields)
    return b"".join((_RECORD_HEAD.pack(opcode, length), *fields))


def _grown(buf: bytearray, used: int, needed: int) -> bytearray:
    """A larger buffer (at least ``needed`` bytes, doubled) holding ``buf[:used]``."""
    new = bytearray(max(2 * len(buf), needed))
    new[:used] = memoryview(buf)[:used]
    return new


class ChunkBuffers:
    """The open chunk of a bag: its records and per-channel message indexes, in buffers that
    grow to a chunk's size and are then reused for every chunk of every file of the session
    (not thread-safe: the bag's lock guards it).

    A zstd context is made per chunk, not kept: kept, its tables stay mapped and their
    resident part changes page by page as chunks hash into them; made per chunk, with the
    node's fixed mmap threshold, it is one mapping taken and given back (the measurements:
    docs/recording.md "Memory over hours").

    :param compression: "zstd", "lz4" or "" (none)
    :param capacity: initial bytes of the record buffer (it grows as needed)
    :raises ValueError: an unknown compression
    """

    def __init__(self, compression: str, capacity: int = INITIAL_CAPACITY) -> None:
        if compression not in ("zstd", "lz4", ""):
            raise ValueError(f"compression {compression!r}: zstd, lz4 or ''")
        self.compression = compression
        self.records = bytearray(capacity)
        self.used = 0
        #: channel id -> [entries buffer, bytes used]
        self.indexes: dict[int, list[Any]] = {}
        self.messages = 0
        self.start_ns = 0
        self.end_ns = 0

    def reset(self) -> None:
        """Empty the chunk, keeping the buffers."""
        self.used = 0
        self.messages = 0
        self.start_ns = self.end_ns = 0
        for entry in self.indexes.values():
            entry[1] = 0

    def _reserve(self, size: int) -> int:
        """Room for ``size`` more bytes of records; returns where they go."""
        at = self.used
        if at + size > len(self.records):
            self.records = _grown(self.records, at, at + size)
        self.used = at + size
        return at

    def add_record(self, data: bytes) -> None:
        """A whole record (schema, channel) into the chunk.

        :param data: the whole record (opcode, length, body)
        """
        at = self._reserve(len(data))
        self.records[at:at + len(data)] = data

    def add_message(self, channel_id: int, sequence: int, log_time_ns: int,
                    publish_time_ns: int, data: bytes) -> None:
        """A message record and its message-index entry, written in place.

        :param channel_id: the message's channel
        :param sequence: its sequence number
        :param log_time_ns: when it was received (ns)
        :param publish_time_ns: when it was sent (ns)
        :param data: its bytes
        """
        size = _MESSAGE.size + len(data)
        at = self._reserve(size)
        _MESSAGE.pack_into(self.records, at, OP_MESSAGE, size - 9, channel_id, sequence,
                           log_time_ns, publish_time_ns)
        self.records[at + _MESSAGE.size:at + size] = data
        entry = self.indexes.get(channel_id)
        if entry is None:
            entry = self.indexes[channel_id] = [bytearray(INITIAL_CAPACITY // 4), 0]
        buf, used = entry
        if used + _INDEX_ENTRY.size > len(buf):
            buf = entry[0] = _grown(buf, used, used + _INDEX_ENTRY.size)
        _INDEX_ENTRY.pack_into(buf, used, log_time_ns, at)
        entry[1] = used + _INDEX_ENTRY.size
        if self.messages == 0:
            self.start_ns = self.end_ns = log_time_ns
        else:
            self.start_ns = min(self.start_ns, log_time_ns)
            self.end_ns = max(self.end_ns, log_time_ns)
        self.messages += 1

    def compressed(self) -> bytes | memoryview:
        """The chunk's records as they go into the Chunk record (a view when uncompressed:
        valid until the next write)."""
        view = memoryview(self.records)[:self.used]
        if self.compression == "zstd":
            return zstandard.ZstdCompressor().compress(view)
        if self.compression == "lz4":
            compressed: bytes = lz4.frame.compress(view)
            return compressed
        return view

    def write_chunk(self, stream: BinaryIO) -> bytes:
        """Write the Chunk record and its message indexes at the stream's position and
        return its ChunkIndex record (for the summary); the chunk is then empty."""
        with memoryview(self.records) as whole:
            crc = zlib.crc32(whole[:self.used])
        data = self.compressed()
        compressed_size = len(data)
        name = _string(self.compression)
        start = stream.tell()
        stream.write(_CHUNK_HEAD.pack(OP_CHUNK, _CHUNK_HEAD.size - 9 + len(name) + 8
                                      + compressed_size, self.start_ns, self.end_ns,
                                      self.used, crc) + name + _U64.pack(compressed_size))
        stream.write(data)
        if isinstance(data, memoryview):
            data.release()
        del data
        index_start = stream.tell()
        offsets = []
        for channel_id in sorted(self.indexes):
            buf, used = self.indexes[channel_id]
            if not used:
                continue
            offsets.append(_U16.pack(channel_id) + _U64.pack(stream.tell()))
            stream.write(_INDEX_HEAD.pack(OP_MESSAGE_INDEX, 6 + used, channel_id, used))
            with memoryview(buf) as entries:
                stream.write(entries[:used])
        offset_map = b"".join(offsets)
        chunk_index = record(
            OP_CHUNK_INDEX,
            struct.pack("<QQQQ", self.start_ns, self.end_ns, start, index_start - start),
            _U32.pack(len(offset_map)), offset_map, _U64.pack(stream.tell() - index_start),
            name, struct.pack("<QQ", compressed_size, self.used))
        self.reset()
        return chunk_index


class McapWriter:
    """One MCAP file (chunked, indexed, with a summary) written through a session's
    :class:`ChunkBuffers`; what it keeps per chunk is its packed ChunkIndex record.

    :param stream: the file's binary stream
    :param chunks: the session's chunk buffers
    :param chunk_size: bytes of a chunk before it is written
    """

    def __init__(self, stream: BinaryIO, chunks: ChunkBuffers, chunk_size: int) -> None:
        self._stream = stream
        self._chunks = chunks
        self._chunk_size = chunk_size
        self._schemas: list[bytes] = []
        self._channels: list[bytes] = []
        self._chunk_indexes: list[bytes] = []
        self._metadata_indexes: list[bytes] = []
        self._channel_counts: dict[int, int] = {}
        self.message_count = 0
        self._start_ns = 0
        self._end_ns = 0

    def start(self, profile: str, library: str) -> None:
        """The magic and the Header record; the chunk buffers start empty.

        :param profile: the Header's profile (``ros2``)
        :param library: the Header's library string
        """
        self._chunks.reset()
        self._stream.write(MAGIC + record(OP_HEADER, _string(profile), _string(library)))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """A Schema record (into the open chunk and the summary); returns its id.

        :param name: the schema's name (the type)
        :param encoding: e.g. ``ros2msg``
        :param data: the schema text
        """
        schema_id = len(self._schemas) + 1
        rec = record(OP_SCHEMA, _U16.pack(schema_id), _string(name), _string(encoding),
                     _U32.pack(len(data)), data)
        self._schemas.append(rec)
        self._chunks.add_record(rec)
        return schema_id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: dict[str, str]) -> int:
        """A Channel record (into the open chunk and the summary); returns its id.

        :param topic: the channel's topic
        :param message_encoding: e.g. ``cdr``
        :param schema_id: a registered schema
        :param metadata: the channel's metadata
        """
        channel_id = len(self._channels) + 1
        rec = record(OP_CHANNEL, _U16.pack(channel_id), _U16.pack(schema_id), _string(topic),
                     _string(message_encoding), _string_map(metadata))
        self._channels.append(rec)
        self._chunks.add_record(rec)
        return channel_id

    def add_message(self, channel_id: int, log_time_ns: int, data: bytes,
                    publish_time_ns: int, sequence: int) -> None:
        """A Message into the open chunk; the chunk is written once it exceeds the size.

        :param channel_id: a registered channel
        :param log_time_ns: when it was received (ns)
        :param data: its bytes
        :param publish_time_ns: when it was sent (ns)
        :param sequence: its sequence number
        """
        self.message_count += 1
        self._channel_counts[channel_id] = self._channel_counts.get(channel_id, 0) + 1
        self._chunks.add_message(channel_id, sequence, log_time_ns, publish_time_ns, data)
        if self._chunks.used > self._chunk_size:
            self._write_chunk()

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """A Metadata record in the data section, indexed in the summary.

        :param name: the record's name
        :param data: its key -> value mapping
        """
        offset = self._stream.tell()
        rec = record(OP_METADATA, _string(name), _string_map(data))
        self._stream.write(rec)
        self._metadata_indexes.append(record(OP_METADATA_INDEX, _U64.pack(offset),
                                             _U64.pack(len(rec)), _string(name)))

    def _write_chunk(self) -> None:
        chunks = self._chunks
        if chunks.messages:
            # the file's message time span is its chunks' (each keeps its own)
            first = not self._chunk_indexes
            self._start_ns = chunks.start_ns if first else min(self._start_ns, chunks.start_ns)
            self._end_ns = chunks.end_ns if first else max(self._end_ns, chunks.end_ns)
            self._chunk_indexes.append(chunks.write_chunk(self._stream))

    def flush(self) -> None:
        """Write the open chunk (if it holds a message) and flush the stream."""
        self._write_chunk()
        self._stream.flush()

    def finish(self) -> None:
        """The last chunk, DataEnd, the summary (schemas, channels, statistics, chunk and
        metadata indexes, summary offsets), the footer and the closing magic."""
        self._write_chunk()
        self._chunks.reset()   # schemas/channels of a file without messages: summary only
        stream = self._stream
        stream.write(record(OP_DATA_END, _U32.pack(0)))
        summary_start = stream.tell()
        counts = b"".join(_U16.pack(c) + _U64.pack(n)
                          for c, n in sorted(self._channel_counts.items()))
        statistics = record(OP_STATISTICS, struct.pack(
            "<QHIIIIQQ", self.message_count, len(self._schemas), len(self._channels), 0,
            len(self._metadata_indexes), len(self._chunk_indexes), self._start_ns,
            self._end_ns), _U32.pack(len(counts)), counts)
        groups = [(OP_SCHEMA, self._schemas), (OP_CHANNEL, self._channels),
                  (OP_STATISTICS, [statistics]), (OP_CHUNK_INDEX, self._chunk_indexes),
                  (OP_METADATA_INDEX, self._metadata_indexes)]
        parts: list[bytes] = []
        offsets: list[bytes] = []
        at = summary_start
        for opcode, records in groups:
            if not records:
                continue
            length = sum(len(r) for r in records)
            offsets.append(record(OP_SUMMARY_OFFSET, struct.pack("<BQQ", opcode, at, length)))
            parts.extend(records)
            at += length
        summary_offset_start = at
        summary = b"".join(parts + offsets)
        crc = zlib.crc32(_FOOTER_FIELDS.pack(OP_FOOTER, 20, summary_start, summary_offset_start),
                         zlib.crc32(summary))
        stream.write(summary)
        stream.write(record(OP_FOOTER, struct.pack("<QQI", summary_start, summary_offset_start,
                                                   crc)) + MAGIC)
        self._chunk_indexes.clear()
