"""record/mcap_write.py: the bag's own MCAP writer against the ``mcap`` reader (CRCs checked,
with and without the summary), every message index entry checked against its chunk, and the
chunk buffers reused across chunks and split files."""

from __future__ import annotations

import io
from pathlib import Path

import lz4.frame
import pytest
import zstandard
from mcap.reader import NonSeekingReader, SeekingReader
from mcap.records import Chunk, MessageIndex
from mcap.stream_reader import StreamReader

from ssi_bridge.record.bag import BagRecorder
from ssi_bridge.record.mcap_write import ChunkBuffers

from .conftest import T0, TOPICS

PERIOD_NS = 1_000_000


def write_bag(directory: Path, compression: str, cycles: int, **kw: float) -> BagRecorder:
    """``cycles`` 1-ms cycles of TOPICS, a flush every 100 cycles (the flush thread's 0.5 s);
    returns the closed recorder."""
    rec = BagRecorder.open(directory, compression=compression, metadata={"k": "v"}, **kw)
    for topic, (type_name, _, _) in TOPICS.items():
        rec.add_topic(topic, type_name)
    for i in range(cycles):
        for topic, (_, make, every) in TOPICS.items():
            if i % every == 0:
                rec.write(topic, make(i), T0 + i * PERIOD_NS, T0 + i * PERIOD_NS - 7)
        if i % 100 == 99:
            rec.flush()
    rec.close()
    return rec


def decompress(chunk: Chunk) -> bytes:
    if chunk.compression == "zstd":
        return zstandard.ZstdDecompressor().decompress(chunk.data,
                                                       max_output_size=chunk.uncompressed_size)
    if chunk.compression == "lz4":
        return lz4.frame.decompress(chunk.data)
    return chunk.data


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_files_read_back_with_crcs_and_indexes(tmp_path: Path, compression: str) -> None:
    rec = write_bag(tmp_path / "bag", compression, 3000, max_duration_s=1.0)
    files = [rec.directory / name for name in rec.files]
    assert len(files) == 3
    total = 0
    for path in files:
        data = path.read_bytes()
        reader = SeekingReader(io.BytesIO(data), validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        messages = [m for _, _, m in reader.iter_messages(log_time_order=False)]
        assert len(messages) == summary.statistics.message_count
        assert sum(summary.statistics.channel_message_counts.values()) == len(messages)
        assert summary.statistics.message_start_time == messages[0].log_time
        assert summary.statistics.message_end_time == messages[-1].log_time
        assert all(m.publish_time == m.log_time - 7 for m in messages)
        assert [m.name for m in reader.iter_metadata()] == ["ssi_bridge", "rosbag2"]
        assert {c.topic for c in summary.channels.values()} == set(TOPICS)
        streamed = list(NonSeekingReader(io.BytesIO(data), validate_crcs=True).iter_messages())
        assert [m.log_time for _, _, m in streamed] == [m.log_time for m in messages]
        total += len(messages)
        # every message index entry points at a message of its channel with its log time
        for index in summary.chunk_indexes:
            assert index.compression == ("" if compression == "none" else compression)
            chunk = next(StreamReader(io.BytesIO(
                data[index.chunk_start_offset:index.chunk_start_offset + index.chunk_length]),
                skip_magic=True, emit_chunks=True).records)
            assert isinstance(chunk, Chunk) and len(chunk.data) == index.compressed_size
            records = decompress(chunk)
            assert len(records) == index.uncompressed_size
            seen = 0
            for channel_id, offset in index.message_index_offsets.items():
                mi = next(StreamReader(io.BytesIO(data[offset:]), skip_magic=True).records)
                assert isinstance(mi, MessageIndex) and mi.channel_id == channel_id
                for log_time, at in mi.records:
                    msg = next(StreamReader(io.BytesIO(records[at:]), skip_magic=True).records)
                    assert (msg.channel_id, msg.log_time) == (channel_id, log_time)
                    seen += 1
            start = index.chunk_start_offset + index.chunk_length
            assert (min(index.message_index_offsets.values()) == start
                    and index.message_index_length > 0)
            assert seen > 0
    assert total == rec.message_count


def test_chunk_buffers_are_kept_across_chunks_and_files(tmp_path: Path) -> None:
    """Why the writer exists (docs/recording.md, "Memory over hours"): once a chunk has
    reached its size, no chunk and no split allocates its buffers again."""
    rec = BagRecorder.open(tmp_path / "bag", max_duration_s=0.5)
    for topic, (type_name, _, _) in TOPICS.items():
        rec.add_topic(topic, type_name)
    chunks: ChunkBuffers = rec._chunks
    seen: set[tuple[int, int]] = set()
    for i in range(5000):
        for topic, (_, make, every) in TOPICS.items():
            if i % every == 0:
                rec.write(topic, make(i), T0 + i * PERIOD_NS)
        if i % 100 == 99:
            rec.flush()
            if i >= 1000:
                seen.add((id(chunks.records), len(chunks.records)))
                seen.update((id(buf), len(buf)) for buf, _ in chunks.indexes.values())
    rec.close()
    assert len(rec.files) == 10
    # one records buffer and one index buffer per channel for 40 chunks in 8 files
    assert len(seen) == 1 + len(TOPICS), seen


def test_a_file_without_messages_leaves_no_records_for_the_next(tmp_path: Path) -> None:
    """Schemas and channels of a file closed before any message go to its summary only."""
    rec = BagRecorder.open(tmp_path / "bag", compression="none")
    rec.add_topic("/joint_states", TOPICS["/joint_states"][0])
    rec.close()
    path = rec.directory / rec.files[0]
    reader = SeekingReader(io.BytesIO(path.read_bytes()), validate_crcs=True)
    summary = reader.get_summary()
    assert summary is not None and summary.chunk_indexes == []
    assert [c.topic for c in summary.channels.values()] == ["/joint_states"]
    assert rec._chunks.used == 0
