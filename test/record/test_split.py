"""Split sessions as rosbag2 writes them: ``<name>_<k>.mcap`` listed in metadata.yaml, each
file a complete MCAP with the configuration and every schema and channel, nothing lost or
duplicated at a split; read back by rosbags, mcap-ros2-support, our reader, plot, recovery."""

from __future__ import annotations

import hashlib
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record.bag import CONFIG_METADATA_NAME, MIN_SPLIT_SIZE, BagRecorder
from ssi_bridge.record.plot import load_session
from ssi_bridge.record.reader import Bag
from ssi_bridge.record.recover import recover_bag

from .conftest import T0, TOPICS

PERIOD_NS = 10_000_000      # 100 Hz cycles: 20 s of session in 2000 cycles
CYCLES = 2000
CHILD = Path(__file__).with_name("split_writer_child.py")


def write_split(directory: Path, cycles: int, **limits: float) -> tuple[Path, list[tuple]]:
    """Record ``cycles`` cycles of TOPICS 10 ms apart with split limits; return the bag and
    every written (topic, log time) in order."""
    rec = BagRecorder.open(directory, metadata={"session": "split test"}, **limits)
    for topic, (type_name, _, _) in TOPICS.items():
        rec.add_topic(topic, type_name)
    written = []
    for i in range(cycles):
        for topic, (_, make, every) in TOPICS.items():
            if i % every == 0:
                t = T0 + i * PERIOD_NS
                rec.write(topic, make(i), t, t - 1000)
                written.append((topic, t))
        if i % 50 == 49:
            rec.flush()     # what the flush thread does every 0.5 s
    summary = rec.close()
    assert summary.message_count == len(written)
    return summary.directory, written


@pytest.fixture(scope="module")
def by_duration(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[tuple]]:
    """A 20 s session split every 5 s."""
    return write_split(tmp_path_factory.mktemp("split") / "twenty", CYCLES, max_duration_s=5)


def info_of(bag: Path) -> dict:
    return yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]


def file_messages(path: Path) -> list[tuple[str, int]]:
    """(topic, log time) of one file in file order, read by mcap alone."""
    with open(path, "rb") as f:
        return [(ch.topic, m.log_time)
                for _, ch, m in make_reader(f).iter_messages(log_time_order=True)]


def test_duration_split_names_and_metadata_like_rosbag2(by_duration) -> None:
    bag, written = by_duration
    info = info_of(bag)
    names = [f"twenty_{k}.mcap" for k in range(4)]
    # rosbag2's rule: a message more than 5 s after the file's first opens the next file,
    # so 20 s at 10 ms hold [0, 5.00], [5.01, 10.01], [10.02, 15.02], [15.03, 19.99]
    assert info["relative_file_paths"] == names
    assert sorted(p.name for p in bag.glob("*.mcap")) == names
    assert [f["path"] for f in info["files"]] == names
    assert sum(f["message_count"] for f in info["files"]) == info["message_count"] == len(written)
    for entry in info["files"]:
        got = file_messages(bag / entry["path"])
        assert entry["message_count"] == len(got)
        times = [t for _, t in got]
        assert entry["starting_time"]["nanoseconds_since_epoch"] == times[0]
        assert entry["duration"]["nanoseconds"] == times[-1] - times[0] <= 5_000_000_000
    starts = [f["starting_time"]["nanoseconds_since_epoch"] for f in info["files"]]
    assert [(s - T0) // PERIOD_NS for s in starts] == [0, 501, 1002, 1503]
    assert info["starting_time"]["nanoseconds_since_epoch"] == T0
    assert info["duration"]["nanoseconds"] == (CYCLES - 1) * PERIOD_NS


def test_no_message_lost_or_duplicated_at_a_split(by_duration) -> None:
    bag, written = by_duration
    files = info_of(bag)["relative_file_paths"]
    joined = [m for name in files for m in file_messages(bag / name)]
    assert Counter(joined) == Counter(written), "every message exactly once over the files"
    stamps = [t for topic, t in joined if topic == "/joint_states"]
    assert stamps == [T0 + i * PERIOD_NS for i in range(CYCLES)], "no gap, no repeat, in order"
    for before, after in zip(files, files[1:]):
        last = file_messages(bag / before)[-1][1]
        first = file_messages(bag / after)[0][1]
        assert first - last == PERIOD_NS, f"{before} -> {after}: the next cycle, not a gap"


def test_every_file_is_a_complete_mcap_with_configuration_and_all_channels(by_duration) -> None:
    bag, _ = by_duration
    for name in info_of(bag)["relative_file_paths"]:
        with open(bag / name, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            assert summary is not None and summary.statistics is not None, name
            assert summary.chunk_indexes, f"{name}: no chunk index"
            assert {c.topic for c in summary.channels.values()} == set(TOPICS), name
            assert {s.name for s in summary.schemas.values()} == {t for t, _, _ in
                                                                   TOPICS.values()}
            records = {m.name: m.metadata for m in reader.iter_metadata()}
        assert records[CONFIG_METADATA_NAME] == {"session": "split test"}, name
        assert "rosbag2" in records, name


def test_rosbags_and_mcap_ros2_read_all_files_with_metadata_counts(by_duration) -> None:
    bag, written = by_duration
    expected = Counter(topic for topic, _ in written)
    info = info_of(bag)
    assert {t["topic_metadata"]["name"]: t["message_count"]
            for t in info["topics_with_message_count"]} == expected
    with AnyReader([bag]) as reader:
        assert Counter(c.topic for c, _, _ in reader.messages()) == expected
        assert reader.message_count == info["message_count"]
    decoded: Counter[str] = Counter()
    for name in info["relative_file_paths"]:
        with open(bag / name, "rb") as f:
            for _, channel, _, msg in make_reader(
                    f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
                decoded[channel.topic] += 1
                assert msg is not None
    assert decoded == expected


def test_our_reader_and_plot_see_the_whole_split_session(by_duration) -> None:
    bag, written = by_duration
    with Bag(bag) as reader:
        assert len(reader.files) == 4
        assert {t.name: t.message_count for t in reader.topics.values()} == \
            Counter(topic for topic, _ in written)
        got = [(topic, m.log_time) for topic, m in reader.messages()]
        assert [t for _, t in got] == sorted(t for _, t in written)
        assert Counter(got) == Counter(written)
        later = T0 + 1200 * PERIOD_NS       # in the third file
        tail = [m.log_time for _, m in reader.messages(["/joint_states"], start_ns=later)]
        assert tail == [T0 + i * PERIOD_NS for i in range(1200, CYCLES)]
    data = load_session(bag)
    assert len(data.joints["axis_1"][0]) == CYCLES
    assert data.end_s == pytest.approx((CYCLES - 1) * PERIOD_NS / 1e9)


def test_size_split_closes_a_file_at_the_first_message_past_max_size(tmp_path: Path) -> None:
    bag, written = write_split(tmp_path / "sized", 1500, max_size=MIN_SPLIT_SIZE)
    info = info_of(bag)
    files = info["relative_file_paths"]
    assert len(files) >= 3
    sizes = [(bag / name).stat().st_size for name in files]
    # a file grows chunk by chunk (one every 0.5 s of data here), so it ends past the limit
    # by less than one chunk plus its summary
    for size in sizes[:-1]:
        assert MIN_SPLIT_SIZE <= size < 2 * MIN_SPLIT_SIZE, sizes
    with AnyReader([bag]) as reader:
        assert sorted((c.topic, t) for c, t, _ in reader.messages()) == sorted(written)


def test_split_limits_below_the_minimum_are_refused(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="max_size 1000: 0 .no split. or at least 65536"):
        BagRecorder.open(tmp_path / "tiny", max_size=1000)
    with pytest.raises(RecordingError, match="max_duration"):
        BagRecorder.open(tmp_path / "neg", max_duration_s=-1)
    assert not (tmp_path / "tiny").exists() and not (tmp_path / "neg").exists()


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_kill_9_in_the_third_file_recovers_only_that_file(tmp_path: Path) -> None:
    bag = tmp_path / "cut"
    proc = subprocess.Popen([sys.executable, str(CHILD), str(bag), "1"], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 60
        third = bag / "cut_2.mcap"
        assert proc.stdout is not None
        for line in proc.stdout:        # "file <k> <n>" right after a flush
            if line.split()[:2] == ["file", "2"]:
                break       # file 2 was opened by a message, and the flush put it on disk
            assert time.monotonic() < deadline, "the child never reached its third file"
        else:
            pytest.fail(f"child exited {proc.wait()} before its third file")
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
        if proc.stdout:
            proc.stdout.close()
    assert not (bag / "metadata.yaml").exists()
    with pytest.raises(RecordingError, match="recover"):
        Bag(bag)
    closed = {name: digest(bag / name) for name in ("cut_0.mcap", "cut_1.mcap")}
    summary = recover_bag(bag)
    assert {name: digest(bag / name) for name in closed} == closed, "closed files untouched"
    assert summary.files[:3] == ("cut_0.mcap", "cut_1.mcap", "cut_2.mcap")
    info = info_of(bag)
    assert info["relative_file_paths"] == list(summary.files)
    assert sum(f["message_count"] for f in info["files"]) == summary.message_count
    assert info["files"][2]["message_count"] > 0, "what reached the disk in file 2 is kept"
    with AnyReader([bag]) as reader:
        stamps = [t for _, t, _ in reader.messages()]
    assert len(stamps) == summary.message_count and stamps == sorted(stamps)
    with Bag(bag) as reopened:
        seq = [m.sequence for _, m in reopened.messages()]
    assert seq == list(range(len(seq))), "no message lost or repeated before the cut"
    assert third.stat().st_size > 0


def test_recover_keeps_complete_files_and_leaves_out_an_empty_last_one(tmp_path: Path) -> None:
    bag, written = write_split(tmp_path / "whole", 700, max_duration_s=2)
    before = {p.name: digest(p) for p in bag.glob("*.mcap")}
    (bag / "metadata.yaml").unlink()
    (bag / f"whole_{len(before)}.mcap").write_bytes(b"")    # a crash as a split began
    summary = recover_bag(bag)
    assert {name: digest(bag / name) for name in before} == before
    assert summary.files == tuple(sorted(before, key=lambda n: int(n[6:-5])))
    assert summary.message_count == len(written)
    with AnyReader([bag]) as reader:
        assert reader.message_count == len(written)
