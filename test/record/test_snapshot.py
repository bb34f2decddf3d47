"""The fault snapshot's ring and writer (record/ring.py, record/snapshot.py) and the bag's
on-demand split, without ROS: real BagRecorder bags read back by rosbags and mcap."""

from __future__ import annotations

import time
from collections import Counter
from pathlib import Path

import can
import pytest
import yaml
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record import cdr
from ssi_bridge.record.bag import BagRecorder
from ssi_bridge.record.can_frames import pack_frame, unpack_frame
from ssi_bridge.record.ring import ENTRY_OVERHEAD, MessageRing
from ssi_bridge.record.snapshot import CAN_LOG, PREFIX, SnapshotConfig, SnapshotKeeper

from support.waiting import wait_for

from .conftest import T0, joint_state

MS = 1_000_000
TOPIC = "/joint_states"
TYPE = "sensor_msgs/msg/JointState"


def test_ring_keeps_the_duration_and_counts_its_bytes():
    ring = MessageRing(1.0)
    data = cdr.serialize(joint_state(0))
    for i in range(3000):  # 3 s at 1 kHz
        ring.append(TOPIC, T0 + i * MS, T0 + i * MS, data)
    assert 1000 <= len(ring) <= 1001
    assert ring.span_ns <= 1_000_000_000
    assert ring.payload_bytes == len(ring) * len(data)
    assert ring.memory_bytes == len(ring) * (len(data) + ENTRY_OVERHEAD)
    first = ring.entries()[0]
    assert first.log_time_ns >= T0 + 1999 * MS and first.topic == TOPIC
    assert ring.dropped == 3000 - len(ring)


def test_ring_refuses_a_duration_of_zero():
    with pytest.raises(ValueError, match="must be > 0"):
        MessageRing(0)


class FakeClock:
    """The log-time clock of the keeper, moved by the test (messages carry the same time)."""

    def __init__(self) -> None:
        self.now = T0

    def __call__(self) -> int:
        return self.now


def keeper(root: Path, clock: FakeClock, **kw) -> SnapshotKeeper:
    config = SnapshotConfig(root=root, duration_s=kw.pop("duration_s", 1.0),
                            after_s=kw.pop("after_s", 0.5), **kw)
    return SnapshotKeeper(config, lambda p: BagRecorder.open(p, metadata={"k": "v"}),
                          lambda t: (TYPE, None), clock_ns=clock)


def feed(k: SnapshotKeeper, clock: FakeClock, start: int, count: int) -> None:
    """``count`` JointStates 1 ms apart from index ``start`` (stamp = index)."""
    for i in range(start, start + count):
        clock.now = T0 + i * MS
        k.add(TOPIC, cdr.serialize(joint_state(i)), clock.now, clock.now)


def wait_written(k: SnapshotKeeper, n: int, clock: FakeClock) -> None:
    deadline = time.monotonic() + 30
    while k.written < n:
        assert time.monotonic() < deadline, f"{k.written} snapshots written, {n} expected"
        clock.now += 10 * MS  # a quiet node: the clock ends the snapshot
        time.sleep(0.05)


def indexes(bag: Path) -> list[int]:
    with AnyReader([bag]) as r:
        out = []
        for c, _, raw in r.messages():
            s = r.deserialize(raw, c.msgtype).header.stamp
            out.append((s.sec * 1_000_000_000 + s.nanosec - T0) // MS)
        return out


def test_a_snapshot_holds_the_ring_and_the_time_after(tmp_path: Path):
    clock = FakeClock()
    k = keeper(tmp_path, clock, duration_s=1.0, after_s=0.5)
    feed(k, clock, 0, 3000)                    # 3 s; the ring holds the last 1 s
    path, extended = k.trigger("joint1", clock.now)
    assert not extended and path.name.startswith(PREFIX) and path.name.endswith("_joint1")
    feed(k, clock, 3000, 1000)                 # 0.5 s go in, the rest ends it
    wait_written(k, 1, clock)
    got = indexes(path)
    assert got == list(range(got[0], 3500)), "every message from t-1 s to t+0.5 s, in order"
    assert 1999 <= got[0] <= 2000
    meta = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == len(got) and meta["custom_data"] == {"k": "v"}
    with open(path / f"{path.name}_0.mcap", "rb") as f:
        assert sum(1 for _ in make_reader(f).iter_messages()) == len(got)


def test_faults_within_a_snapshot_extend_it(tmp_path: Path):
    clock = FakeClock()
    k = keeper(tmp_path, clock, duration_s=1.0, after_s=0.5)
    feed(k, clock, 0, 1500)
    first, _ = k.trigger("joint1", clock.now)
    feed(k, clock, 1500, 300)
    assert k.trigger("joint2", clock.now) == (first, True)
    feed(k, clock, 1800, 300)
    assert k.trigger("bus", clock.now) == (first, True)
    feed(k, clock, 2100, 2000)
    wait_written(k, 1, clock)
    assert [p.name for p in tmp_path.iterdir()] == [first.name], "one bag for three faults"
    got = indexes(first)
    assert got == list(range(got[0], 2600)), "to 0.5 s after the last trigger, none missing"


def test_max_bags_removes_the_oldest(tmp_path: Path):
    clock = FakeClock()
    k = keeper(tmp_path, clock, duration_s=0.1, after_s=0.0, max_bags=2)
    paths = []
    for n in range(4):
        feed(k, clock, n * 1000, 200)
        paths.append(k.trigger(f"fault{n}", clock.now)[0])
        feed(k, clock, n * 1000 + 200, 10)
        wait_written(k, n + 1, clock)
        time.sleep(0.02)  # distinct directory times
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == sorted(p.name for p in paths[2:])


def test_a_failed_snapshot_is_reported_and_the_ring_goes_on(tmp_path: Path):
    clock = FakeClock()
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    k = keeper(blocker, clock)
    feed(k, clock, 0, 100)
    k.trigger("joint1", clock.now)
    wait_for(lambda: k.error, "no snapshot write error reported within 10 s", 10, poll=0.02)
    assert "not written" in k.error
    feed(k, clock, 100, 100)
    assert len(k.ring) == 200 and k.counters()["snapshot_writing"] == 0


def test_split_on_demand_starts_the_next_file_at_once(tmp_path: Path):
    rec = BagRecorder.open(tmp_path / "bag")
    rec.add_topic(TOPIC, TYPE)
    with pytest.raises(RecordingError, match="holds no message yet"):
        rec.split()
    for i in range(10):
        rec.write(TOPIC, joint_state(i), T0 + i * MS)
    assert rec.split() == "bag_1.mcap"
    assert (tmp_path / "bag" / "bag_1.mcap").exists()
    for i in range(10, 25):
        rec.write_serialized(TOPIC, cdr.serialize(joint_state(i)), T0 + i * MS)
    summary = rec.close()
    assert summary.files == ("bag_0.mcap", "bag_1.mcap")
    meta = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())
    files = meta["rosbag2_bagfile_information"]["files"]
    assert [f["message_count"] for f in files] == [10, 15]
    with AnyReader([tmp_path / "bag"]) as r:
        assert Counter(c.topic for c, _, _ in r.messages()) == {TOPIC: 25}


def test_frames_pack_to_counted_bytes_and_back():
    msg = can.Message(arbitration_id=0x181, data=bytes(range(8)), is_extended_id=False)
    raw = pack_frame(msg, 1700000000.25)
    assert len(raw) == 24
    back = unpack_frame(raw)
    assert back.timestamp == 1700000000.25 and back.equals(msg, timestamp_delta=None)
    ext = can.Message(arbitration_id=0x1ABCDEF, is_extended_id=True, is_remote_frame=True, dlc=4)
    assert unpack_frame(pack_frame(ext, 1.0)).equals(ext, timestamp_delta=None)


def test_a_snapshot_with_can_log_writes_the_frames_beside_the_bag(tmp_path: Path):
    clock = FakeClock()
    k = keeper(tmp_path, clock, duration_s=1.0, after_s=0.5, can_log=True)
    for i in range(3000):
        clock.now = T0 + i * MS
        k.add(TOPIC, cdr.serialize(joint_state(i)), clock.now, clock.now)
        k.add_frame(clock.now, pack_frame(can.Message(arbitration_id=0x80, data=b"",
                                                      is_extended_id=False), clock.now / 1e9))
    path, _ = k.trigger("joint1", clock.now)
    for i in range(3000, 4000):
        clock.now = T0 + i * MS
        k.add_frame(clock.now, pack_frame(can.Message(arbitration_id=0x181, data=b"\x01",
                                                      is_extended_id=False), clock.now / 1e9))
        k.add(TOPIC, cdr.serialize(joint_state(i)), clock.now, clock.now)
    wait_written(k, 1, clock)
    frames = list(can.LogReader(str(path / CAN_LOG)))
    ids = Counter(f.arbitration_id for f in frames)
    assert 999 <= ids[0x80] <= 1001 and ids[0x181] == 500, ids
    times = [f.timestamp for f in frames]
    assert times == sorted(times)
    assert abs(times[-1] - (T0 + 3499 * MS) / 1e9) < 1e-3
    assert k.counters()["snapshot_can_ring_bytes"] > 0


def test_can_frames_that_lag_the_messages_still_reach_the_snapshot(tmp_path: Path):
    """The frames come through a listener of their own: on a loaded machine they may arrive
    after the messages that end the snapshot. The CAN log waits for them until a frame stamped
    after the snapshot's end comes (FRAME_GRACE_S at most), so every frame of its time is in."""
    clock = FakeClock()
    k = keeper(tmp_path, clock, duration_s=1.0, after_s=0.5, can_log=True)
    sync = lambda t: pack_frame(can.Message(arbitration_id=0x80, data=b"",  # noqa: E731
                                            is_extended_id=False), t / 1e9)
    for i in range(2000):
        clock.now = T0 + i * MS
        k.add(TOPIC, cdr.serialize(joint_state(i)), clock.now, clock.now)
        k.add_frame(clock.now, sync(clock.now))
    path, _ = k.trigger("joint1", clock.now)
    lag = 200  # the frames run 200 ms behind the messages
    for i in range(2000, 2700):
        clock.now = T0 + i * MS
        k.add(TOPIC, cdr.serialize(joint_state(i)), clock.now, clock.now)  # ends it at 2500
        if i - lag >= 2000:
            k.add_frame(T0 + (i - lag) * MS, sync(T0 + (i - lag) * MS))
    wait_written(k, 1, clock)
    stamps = [round(f.timestamp * 1e3) for f in can.LogReader(str(path / CAN_LOG))]
    last = round((T0 + 2499 * MS) / 1e6)
    assert stamps[-1] == last, (stamps[-1], last)
    assert len(stamps) == len(set(stamps)) == stamps[-1] - stamps[0] + 1, "none lost, none twice"
