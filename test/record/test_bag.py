"""BagRecorder: rosbag2 layout, read back by mcap-ros2-support and rosbags with equal content."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record.bag import BagRecorder
from ssi_bridge.record.schema import SEPARATOR, build_schema

from .conftest import T0, TOPICS, joint_state, write_session

N = 2000
EXPECTED = {topic: len(range(0, N, every)) for topic, (_, _, every) in TOPICS.items()}


def test_layout_and_metadata_yaml(session_bag: Path) -> None:
    files = sorted(p.name for p in session_bag.iterdir())
    assert files == ["metadata.yaml", "session_0.mcap"], files
    info = yaml.safe_load((session_bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == ["session_0.mcap"]
    assert info["message_count"] == sum(EXPECTED.values())
    assert info["starting_time"]["nanoseconds_since_epoch"] == T0
    assert info["duration"]["nanoseconds"] == (N - 1) * 1_000_000
    counts = {t["topic_metadata"]["name"]: t["message_count"]
              for t in info["topics_with_message_count"]}
    assert counts == EXPECTED
    for t in info["topics_with_message_count"]:
        assert t["topic_metadata"]["serialization_format"] == "cdr"
        assert t["topic_metadata"]["type_description_hash"].startswith("RIHS01_")
    assert info["custom_data"]["encoder_families"] == "axis_1: TR CE58M"


def test_mcap_records_follow_rosbag2(session_bag: Path) -> None:
    with open(session_bag / "session_0.mcap", "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert header.profile == "ros2"
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == sum(EXPECTED.values())
    assert summary.chunk_indexes and all(c.compression == "zstd" for c in summary.chunk_indexes)
    assert all(c.message_index_offsets for c in summary.chunk_indexes)
    assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
    yaml_text = (session_bag / "metadata.yaml").read_text()
    for channel in summary.channels.values():
        assert channel.message_encoding == "cdr"
        qos = channel.metadata["offered_qos_profiles"]
        assert qos.startswith("- history: keep_last")
        # the very text of the channel metadata, indented, is in metadata.yaml
        indented = "\n".join("      " + line for line in qos.splitlines())
        assert indented in yaml_text
        assert channel.metadata["topic_type_hash"].startswith("RIHS01_")
    assert "rosbag2" in metadata and "serialized_metadata" in metadata["rosbag2"]
    assert metadata["ssi_bridge"]["encoder_families"] == "axis_1: TR CE58M"


def test_schema_has_dependencies_in_rosbag2_form() -> None:
    text = build_schema("ssi_bridge_msgs/msg/Status").text
    assert f"\n{SEPARATOR}\nMSG: std_msgs/Header\n" in text
    assert f"\n{SEPARATOR}\nMSG: builtin_interfaces/Time\n" in text
    assert f"\n{SEPARATOR}\nMSG: ssi_bridge_msgs/ChannelStatus\n" in text
    assert text.startswith("# Per-cycle status")


def test_two_readers_agree_on_counts_types_stamps_values(session_bag: Path) -> None:
    mcap_msgs: list[tuple[str, int, int, object]] = []
    with open(session_bag / "session_0.mcap", "rb") as f:
        for schema, channel, message, decoded in make_reader(
                f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            mcap_msgs.append((channel.topic, message.log_time, message.publish_time, decoded))
    rb_msgs: list[tuple[str, int, object]] = []
    with AnyReader([session_bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        for conn, stamp, raw in reader.messages():
            rb_msgs.append((conn.topic, stamp, reader.deserialize(raw, conn.msgtype)))
    assert types == {t: v[0] for t, v in TOPICS.items()}
    assert len(mcap_msgs) == len(rb_msgs) == sum(EXPECTED.values())
    for (topic, log, pub, a), (rtopic, rstamp, b) in zip(
            sorted(mcap_msgs, key=lambda m: (m[1], m[0])),
            sorted(rb_msgs, key=lambda m: (m[1], m[0]))):
        assert (topic, log) == (rtopic, rstamp)
        assert pub == log - 1000
        i = (log - T0) // 1_000_000
        if topic == "/joint_states":
            assert list(a.position) == list(b.position) == [0.001 * i, -0.002 * i]
            assert a.header.stamp.nanosec == b.header.stamp.nanosec
            assert a.name == list(b.name) == ["axis_1", "axis_2"]
        elif topic == "/ssi_bridge/status":
            assert [c.samples for c in a.channels] == [c.samples for c in b.channels] == [i, i]
            assert list(a.channels[1].process_input) == list(b.channels[1].process_input)
            assert b.channels[1].reg_ssi_pos == i - 5
        elif topic == "/diagnostics":
            assert a.status[0].level == b.status[0].level == (i // 10) % 3


@pytest.mark.parametrize("compression", ["lz4", "none"])
def test_other_compressions_read_by_rosbags(tmp_path: Path, compression: str) -> None:
    bag = write_session(tmp_path / "bag", 300, compression)
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        assert reader.message_count == sum(len(range(0, 300, e)) for _, _, e in TOPICS.values())
        assert sum(1 for _ in reader.messages()) == reader.message_count


def test_concurrent_writers(tmp_path: Path) -> None:
    rec = BagRecorder.open(tmp_path / "threads", flush_period_s=0.01)
    for k in range(4):
        rec.add_topic(f"/t{k}", "sensor_msgs/msg/JointState")

    def worker(k: int) -> None:
        for i in range(500):
            rec.write(f"/t{k}", joint_state(i), T0 + i)

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    summary = rec.close()
    assert summary.message_count == 2000 and summary.topics == {f"/t{k}": 500 for k in range(4)}
    with AnyReader([tmp_path / "threads"]) as reader:
        assert sum(1 for _ in reader.messages()) == 2000


def test_a_message_handed_over_late_is_logged_in_order_in_every_file(tmp_path: Path) -> None:
    """An ~/events message whose thread read the clock 7 ms before a joint_states message but
    wrote after it (preempted in between) was logged 7 ms before its predecessor: ``mcap
    doctor --strict-message-order`` failed. It is logged at the latest log time instead, its
    publish time kept; the next file of a split starts no earlier either."""
    from ..conftest import log_time_disorder

    ms = 1_000_000
    rec = BagRecorder.open(tmp_path / "late")
    rec.add_topic("/joint_states", "sensor_msgs/msg/JointState")
    rec.add_topic("/ssi_bridge/events", "ssi_bridge_msgs/msg/Event")
    make_event = TOPICS["/ssi_bridge/events"][1]
    rec.write("/joint_states", joint_state(10), T0 + 10 * ms)
    rec.write("/ssi_bridge/events", make_event(3), T0 + 3 * ms, T0 + 3 * ms)
    rec.write("/joint_states", joint_state(20), T0 + 20 * ms)
    rec.split()
    rec.write("/ssi_bridge/events", make_event(15), T0 + 15 * ms, T0 + 15 * ms)
    rec.write("/joint_states", joint_state(30), T0 + 30 * ms)
    summary = rec.close()
    assert not log_time_disorder(tmp_path / "late")
    logged = []
    for name in summary.files:
        with open(tmp_path / "late" / name, "rb") as f:
            logged.append([(ch.topic, m.log_time - T0, m.publish_time - T0)
                           for _, ch, m in make_reader(f).iter_messages(log_time_order=False)])
    assert logged == [
        [("/joint_states", 10 * ms, 10 * ms), ("/ssi_bridge/events", 10 * ms, 3 * ms),
         ("/joint_states", 20 * ms, 20 * ms)],
        [("/ssi_bridge/events", 20 * ms, 15 * ms), ("/joint_states", 30 * ms, 30 * ms)]]
    assert summary.duration == pytest.approx(0.020)


@pytest.mark.parametrize(("setup", "match"), [
    (lambda p: p.mkdir(), "already exists"),
    (lambda p: p.parent.joinpath("file").write_text("x"), "cannot create bag"),
])
def test_open_refusals(tmp_path: Path, setup, match: str) -> None:  # type: ignore[no-untyped-def]
    target = tmp_path / "bag"
    setup(target)
    if match == "cannot create bag":
        target = tmp_path / "file" / "bag"
    with pytest.raises(RecordingError, match=match):
        BagRecorder.open(target)


def test_misuse_is_a_recording_error(tmp_path: Path) -> None:
    rec = BagRecorder.open(tmp_path / "bag")
    with pytest.raises(RecordingError, match="was not added"):
        rec.write("/nope", joint_state(0), T0)
    with pytest.raises(RecordingError, match="expected 'pkg/msg/Type'"):
        rec.add_topic("/x", "JointState")
    with pytest.raises(RecordingError, match="not installed"):
        rec.add_topic("/x", "no_such_pkg/msg/Thing")
    rec.close()
    with pytest.raises(RecordingError, match="closed"):
        rec.write("/nope", joint_state(0), T0)
    with pytest.raises(RecordingError, match="compression"):
        BagRecorder.open(tmp_path / "other", compression="gzip")


def test_a_name_whose_files_cannot_exist_is_refused_and_leaves_nothing(tmp_path):
    """Linux file names are at most 255 bytes: a bag called with a 255-character name made its
    directory and then failed on '<name>_0.mcap', leaving the empty directory behind."""
    from ssi_bridge.exceptions import RecordingError
    from ssi_bridge.record.bag import BagRecorder

    before = sorted(tmp_path.iterdir())
    with pytest.raises(RecordingError, match="too long"):
        BagRecorder.open(tmp_path / ("x" * 255))
    assert sorted(tmp_path.iterdir()) == before
    rec = BagRecorder.open(tmp_path / ("y" * 244))  # 244 + len("_99999.mcap") = 255
    rec.close()
    assert (tmp_path / ("y" * 244) / ("y" * 244 + "_0.mcap")).exists()
