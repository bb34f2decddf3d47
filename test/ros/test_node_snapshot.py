"""Fault snapshots (#25 item 1): a node with ``record.snapshot.duration: 5`` at 500 Hz writes,
when a joint goes ERROR (DATA_WIRE_BREAK through ``~/inject_fault``), one bag with every
joint_states message from 5 s before the fault to ``after`` s past the last one, the ERROR
diagnostics in it; three faults within the snapshot give one bag; ``~/snapshot`` writes one on
demand. The stamps are counted against the publish rate, allowing what the node itself counts
as lost (``cycles_missed``, ``incomplete_cycles`` on the bus status)."""

from __future__ import annotations

import os
import statistics
import time
from pathlib import Path

import can
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from ssi_bridge_msgs.srv import InjectFault

from .conftest import wait_for_level

RATE = 500.0
PERIOD_NS = int(1e9 / RATE)
DURATION = 5.0
AFTER = 5.0
K = InjectFault.Request
JOINT1 = "/ssi_bridge: joint1"
BUS = "/ssi_bridge: bus"
SYNC_COB_ID = 0x080


def ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def joint1_error(arr) -> bool:
    """A DiagnosticArray (rclpy's or rosbags', whose level is an int) with joint1 at ERROR."""
    return any(st.name == JOINT1 and st.level in (DiagnosticStatus.ERROR, 2) for st in arr.status)


def snapshots(root: Path) -> list[Path]:
    return sorted(p for p in root.glob("snapshot_*") if (p / "metadata.yaml").exists())


def lost_between(diags: list, t0: int, t1: int) -> int:
    """Cycles the node counts as lost (missed + incomplete) from the last bus status at or
    before ``t0`` to the first at or after ``t1`` (header stamps)."""
    def lost(arr) -> int | None:
        for st in arr.status:
            if st.name == BUS:
                v = {kv.key: kv.value for kv in st.values}
                return int(v["cycles_missed"]) + int(v["incomplete_cycles"])
        return None
    before = [lost(a) for _, a in diags if ns(a.header.stamp) <= t0]
    after = [lost(a) for _, a in diags if ns(a.header.stamp) >= t1]
    assert before and after, "bus statuses on both sides of the snapshot"
    return after[0] - before[-1]


def read_bag(bag: Path) -> tuple[list[tuple[int, int]], list[tuple[int, object]]]:
    """(log time, stamp) of every joint_states message and (log time, DiagnosticArray)."""
    states, diags = [], []
    with AnyReader([bag]) as r:
        for conn, log_time, raw in r.messages():
            msg = r.deserialize(raw, conn.msgtype)
            if conn.topic.endswith("joint_states"):
                states.append((log_time, ns(msg.header.stamp)))
            elif conn.topic == "/diagnostics":
                diags.append((log_time, msg))
    return states, diags


def test_three_faults_give_one_complete_snapshot_with_the_error(running, probe, tmp_path):
    root = tmp_path / "rec"
    node = running({"publish_rate": RATE, "record.root": str(root),
                    "record.snapshot.duration": DURATION, "record.snapshot.after": AFTER})
    diags = probe.subscribe(DiagnosticArray, "/diagnostics", qos=1000)
    received = probe.subscribe(JointState, node.topic("joint_states"), qos=QoSProfile(
        depth=10000, reliability=ReliabilityPolicy.RELIABLE))
    wait_for_level(probe, node, diags, JOINT1, DiagnosticStatus.OK, 10.0)
    time.sleep(DURATION + 1.0)  # the ring is full
    for n in range(3):  # three faults, each within AFTER s of the one before
        res = probe.call(InjectFault, node.topic("~/inject_fault"),
                         K(joint="joint1", kind=K.DATA_WIRE_BREAK))
        assert res.success, res.message
        wait_for_level(probe, node, diags, JOINT1, DiagnosticStatus.ERROR, 5.0)
        if n < 2:
            assert probe.call(InjectFault, node.topic("~/inject_fault"),
                              K(joint="joint1", kind=K.CLEAR_ALL)).success
            wait_for_level(probe, node, diags, JOINT1, DiagnosticStatus.OK, 5.0)
    probe.wait_for(lambda: "snapshot written" in node.log(), 30.0, "the snapshot closed", node)
    bags = snapshots(root)
    assert len(bags) == 1, f"three faults in one snapshot give one bag: {bags}"
    bag = bags[0]
    assert bag.name.endswith("_joint1"), bag.name
    assert node.log().count("snapshot " + bag.name + " extended") == 2, node.log()[-3000:]

    states, bag_diags = read_bag(bag)
    levels = [(t, joint1_error(arr)) for t, arr in bag_diags]
    # the triggers: joint1's ERROR after a status that was not
    errors = [t for (t, e), (_, before) in zip(levels, [(0, False)] + levels) if e and not before]
    assert len(errors) == 3, f"the three ERROR diagnostics are in the snapshot: {levels}"
    fault_first = errors[0]
    # the ring: 5 s before the first fault; after the last: AFTER s
    assert states[0][0] <= fault_first - int((DURATION - 0.2) * 1e9), \
        (fault_first - states[0][0]) / 1e9
    assert states[-1][0] >= errors[-1] + int((AFTER - 0.3) * 1e9), \
        (states[-1][0] - errors[-1]) / 1e9
    stamps = [s for _, s in states]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps), "in order, no duplicate"
    # every message a subscriber received within the snapshot's span is in it
    probe.wait_for(lambda: ns(received[-1][1].header.stamp) >= stamps[-1], 10.0,
                   "joint_states past the snapshot's end", node)
    seen = {t for _, m in received if stamps[0] <= (t := ns(m.header.stamp)) <= stamps[-1]}
    assert seen <= set(stamps), f"{len(seen - set(stamps))} received messages not in the snapshot"
    # and the stamps against the rate: a SYNC may go up to half a period late without a
    # skipped slot (ros/cycle.py), so a gap counts as lost cycles from 1.7 periods on
    missing = sum(int((b - a) / PERIOD_NS + 0.3) - 1 for a, b in zip(stamps, stamps[1:]))
    probe.wait_for(lambda: ns(diags[-1][1].header.stamp) >= stamps[-1], 10.0,
                   "a bus status after the snapshot's end", node)
    allowed = lost_between(diags, stamps[0], stamps[-1])
    assert missing <= allowed, (f"{missing} cycles missing from the snapshot, the node counts "
                                f"{allowed} lost over its span ({len(stamps)} messages)")
    with open(bag / f"{bag.name}_0.mcap", "rb") as f:
        assert sum(1 for _ in make_reader(f).iter_messages()) >= len(states)

    bus = [st for _, a in diags for st in a.status if st.name == BUS][-1]
    values = {kv.key: kv.value for kv in bus.values}
    ring = int(values["snapshot_ring_bytes"])
    # 5 s of joint_states + status (+ 1 Hz diagnostics): bounded by the duration, ≈ 570 B
    # per cycle of one joint (docs/recording.md "Fault snapshots")
    assert 0 < ring < DURATION * RATE * 1024, values
    assert float(values["snapshot_ring_s"]) <= DURATION + 0.1


def test_snapshot_on_request_and_off_without_a_duration(running, start_node, probe, tmp_path):
    root = tmp_path / "rec"
    node = running({"record.root": str(root), "record.snapshot.duration": 1.0,
                    "record.snapshot.after": 0.5, "record.snapshot.on_error": False,
                    "record.can_log": True})
    time.sleep(1.2)
    res = probe.call(Trigger, node.topic("~/snapshot"), Trigger.Request())
    assert res.success and "snapshot_" in res.message and res.message.endswith("_request"), \
        res.message
    probe.wait_for(lambda: len(snapshots(root)) == 1, 20.0, "the requested snapshot", node)
    bag = snapshots(root)[0]
    states, _ = read_bag(bag)
    span = (states[-1][0] - states[0][0]) / 1e9
    assert 1.2 <= span <= 1.8, span
    # record.can_log: the raw frames of the same time beside the bag, a SYNC per cycle
    frames = list(can.LogReader(str(bag / "can_0.log")))
    syncs = [f.timestamp for f in frames if f.arbitration_id == SYNC_COB_ID]
    assert len(syncs) >= len(states) - 2, (len(syncs), len(states))
    assert syncs[0] <= states[0][1] / 1e9 + 0.05 and syncs[-1] >= states[-1][1] / 1e9 - 0.05

    other = running({"record.root": str(tmp_path / "off")}, namespace="/off")
    res = probe.call(Trigger, other.topic("~/snapshot"), Trigger.Request())
    assert not res.success and "record.snapshot.duration is 0" in res.message, res.message


#: the slow case's length (s); SSI_BRIDGE_SNAPSHOT_SOAK_S shortens it to try the test itself
SOAK_S = float(os.environ.get("SSI_BRIDGE_SNAPSHOT_SOAK_S", 600))


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS")


@pytest.mark.timeout(SOAK_S + 300)
def test_memory_stays_bounded_with_snapshots_over_ten_minutes(running, probe, tmp_path):
    """Slow (test/conftest.py SLOW): 10 minutes at 500 Hz with a 5-s ring, a DATA_WIRE_BREAK
    of 1 s every 30 s (a snapshot each, at most 3 kept): the ring stays within its bound and
    the node's RSS, once the ring is full and the first snapshots are written, grows less
    than 2 MB (median of a minute against median of a minute)."""
    root = tmp_path / "rec"
    node = running({"publish_rate": RATE, "record.root": str(root), "record.snapshot.duration":
                    DURATION, "record.snapshot.after": AFTER, "record.snapshot.max_bags": 3})
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    start = time.monotonic()
    samples: list[tuple[float, float]] = []
    next_fault = start + DURATION + 1.0
    while (now := time.monotonic()) - start < SOAK_S:
        if now >= next_fault:
            assert probe.call(InjectFault, node.topic("~/inject_fault"),
                              K(joint="joint1", kind=K.DATA_WIRE_BREAK, duration=1.0)).success
            next_fault += 30.0
        samples.append((now - start, rss_mb(node.proc.pid)))
        time.sleep(5.0)
    values = {}
    for _, arr in reversed(diags):
        bus = [st for st in arr.status if st.name == BUS]
        if bus:
            values = {kv.key: kv.value for kv in bus[0].values}
            break
    assert 0 < int(values["snapshot_ring_bytes"]) < DURATION * RATE * 1024, values
    assert int(values["snapshots_written"]) >= SOAK_S // 30 - 1, values
    assert len(snapshots(root)) <= 3, "record.snapshot.max_bags bounds the disk"
    # what the node keeps: the median RSS of the first minute after the ring filled against
    # that of the last minute (a snapshot being written adds ~1 MB for a few seconds, freed
    # when its bag is closed; one sample in six falls on it, the median does not)
    begin = min(60.0, SOAK_S / 3)
    first = statistics.median(mb for t, mb in samples if begin <= t < begin + 60.0)
    last = statistics.median(mb for t, mb in samples if t >= SOAK_S - 60.0)
    assert last - first < 2.0, (f"RSS grew {last - first:.2f} MB (median of the minute from "
                                f"{begin:g} s to that of the last minute): {samples}")
