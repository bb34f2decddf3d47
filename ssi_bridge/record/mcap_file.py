"""One MCAP file of a bag being written: its stream, its MCAP writer and its channel ids.

A bag split into several files writes each through its own :class:`McapFile`, so the chunk
index the writer keeps for the summary belongs to the open file and is released when the
file is finished; nothing per chunk outlives its file. The chunk buffers are the session's
(:class:`~ssi_bridge.record.mcap_write.ChunkBuffers`), handed from file to file, so neither
a chunk nor a split allocates them anew.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from ssi_bridge.record.mcap_write import ChunkBuffers, McapWriter
from ssi_bridge.record.metadata import FileInfo, TopicInfo


@dataclass
class Channel:
    """One registered topic: what every file's channel is made from, and the session count."""

    info: TopicInfo
    schema_text: bytes
    channel_meta: dict[str, str]
    sequence: int = 0


class McapFile:
    """An MCAP file open for writing, profile ``ros2``; ``info`` counts what it holds.

    :param path: the file
    :param stream: its open binary stream
    :param writer: the MCAP writer on ``stream``
    """

    def __init__(self, path: Path, stream: BinaryIO, writer: McapWriter, info: FileInfo) -> None:
        self.path = path
        self.info = info
        self._stream = stream
        self._writer: McapWriter | None = writer
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}

    @classmethod
    def create(cls, path: Path, info: FileInfo, chunks: ChunkBuffers, chunk_size: int,
               library: str) -> McapFile:
        """Create ``path`` (it must not exist) and write the MCAP magic and header; its
        chunks go through ``chunks`` (compressed as those say).

        :param info: what the file holds, counted as it is written
        :param chunk_size: bytes of a chunk before it is written
        :param library: the Header's library string
        """
        stream = open(path, "xb")  # noqa: SIM115 - closed in sync_close() / abandon()
        try:
            writer = McapWriter(stream, chunks, chunk_size)
            writer.start(profile="ros2", library=library)
        except OSError:
            with contextlib.suppress(OSError):
                stream.close()
            raise
        return cls(path, stream, writer, info)

    @classmethod
    def start(cls, path: Path, info: FileInfo, chunks: ChunkBuffers, chunk_size: int,
              library: str, config: dict[str, str], config_name: str,
              channels: Mapping[str, Channel], *, remove_on_failure: bool) -> McapFile:
        """Create ``path`` with the header, the configuration metadata record and every
        schema and channel, in the file's first chunk (the first message completes it), so
        each file of a bag stands alone.

        Parameters ``path``, ``info``, ``chunks``, ``chunk_size`` and ``library`` as
        :meth:`create`.

        :param config: the session configuration (none written when empty), named ``config_name``
        :param channels: the bag's topics so far, by name
        :param remove_on_failure: delete the file when writing its start fails
        :raises OSError: the file cannot be created or written (it is abandoned)
        """
        file = cls.create(path, info, chunks, chunk_size, library)
        try:
            if config:
                file.add_metadata(config_name, config)
            for name, channel in channels.items():
                file.add_channel(name, channel.info.type, channel.schema_text,
                                 channel.channel_meta)
            file.flush()
        except OSError:
            file.abandon()
            if remove_on_failure:
                path.unlink(missing_ok=True)
            raise
        return file

    @property
    def size(self) -> int:
        """Bytes written to the file so far (the open chunk not included)."""
        return self._stream.tell()

    def fileno(self) -> int:
        """The file descriptor (for fsync)."""
        return self._stream.fileno()

    def _live(self) -> McapWriter:
        if self._writer is None:
            raise ValueError(f"{self.path} is finished")
        return self._writer

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """An MCAP metadata record (indexed in the summary).

        :param name: the record's name
        :param data: its key -> value mapping
        """
        self._live().add_metadata(name, data)

    def add_channel(self, topic: str, schema_name: str, schema_text: bytes,
                    metadata: dict[str, str]) -> None:
        """Register ``topic`` (cdr) with its ``ros2msg`` schema, the schema once per type.

        :param schema_name: the type ``pkg/msg/Type``
        :param schema_text: its ``ros2msg`` text with dependencies
        :param metadata: the channel's metadata (offered QoS, type hash)
        """
        writer = self._live()
        if schema_name not in self._schemas:
            self._schemas[schema_name] = writer.register_schema(schema_name, "ros2msg",
                                                                schema_text)
        self._channels[topic] = writer.register_channel(topic, "cdr", self._schemas[schema_name],
                                                        metadata)

    def write(self, topic: str, log_time_ns: int, data: bytes, publish_time_ns: int,
              sequence: int) -> None:
        """Append one message of a registered topic.

        :param log_time_ns: when it was received (ns)
        :param data: its CDR bytes
        :param publish_time_ns: when it was sent (ns)
        :param sequence: its sequence number on the topic
        """
        self._live().add_message(self._channels[topic], log_time_ns, data, publish_time_ns,
                                 sequence)
        self.info.add(log_time_ns)

    def flush(self) -> None:
        """Close the open chunk and hand the bytes to the OS."""
        self._live().flush()

    def finish(self) -> None:
        """Write the last chunk, the summary (schemas, channels, statistics, chunk and metadata
        indexes) and the footer; the file is a complete MCAP once this returns. The writer and
        its chunk index are dropped."""
        self._live().finish()
        self._writer = None
        self._stream.flush()

    def sync_close(self) -> None:
        """fsync and close the (finished) file."""
        self._stream.flush()
        os.fsync(self._stream.fileno())
        self._stream.close()

    def abandon(self) -> None:
        """Close after a write error, ignoring further errors (recovery rebuilds the file)."""
        self._writer = None
        with contextlib.suppress(OSError, ValueError):
            self._stream.close()
