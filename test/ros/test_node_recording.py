"""A session recorded by the node opens in two independent readers with the same content,
explains itself with events, and carries the raw CAN traffic when asked (ARCHITECTURE.md:
rosbag2 bag directory, MCAP profile ros2, offered_qos_profiles on every channel)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import can
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.srv import StartRecording, StopRecording, WriteRegister

SYNC_COB_ID = 0x080


def test_session_reads_the_same_in_mcap_and_rosbags_with_events_and_can_log(running, probe,
                                                                             tmp_path: Path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    root = tmp_path / "rec"
    node = running({"record.root": str(root), "record.can_log": True})
    start = probe.call(StartRecording, node.topic("~/start_recording"),
                       StartRecording.Request(path="session"))
    assert start.success, start.message
    msgs = probe.subscribe(JointState, node.topic("joint_states"))
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    probe.wait_for(lambda: len(msgs) > 30 and len(diags) > 0, 10.0,
                   "joint_states and diagnostics while recording", node)
    wrote = probe.call(WriteRegister, node.topic("~/write_register"),
                       WriteRegister.Request(address=34, value=1234))
    assert wrote.success, wrote.message
    stop = probe.call(StopRecording, node.topic("~/stop_recording"), StopRecording.Request())
    assert stop.success, stop.message
    bag = Path(stop.bag_directory)

    with open(bag / "session_0.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        mcap_counts = Counter(ch.topic for _, ch, _ in reader.iter_messages())
        f.seek(0)
        decoded = [(ch.topic, m) for _, ch, _, m in make_reader(
            f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()]
        events = [m for topic, m in decoded if topic.endswith("/events")]
    with AnyReader([bag]) as r:
        rb_counts = Counter(c.topic for c, _, _ in r.messages())
        types = {c.topic: c.msgtype for c in r.connections}
    assert mcap_counts == rb_counts, "rosbags must read every message mcap reads"
    assert stop.message_count == sum(mcap_counts.values())
    js = node.topic("joint_states")
    assert types[js] == "sensor_msgs/msg/JointState"
    assert types[node.topic("~/status")] == "ssi_bridge_msgs/msg/Status"
    assert types["/diagnostics"] == "diagnostic_msgs/msg/DiagnosticArray"
    # one ~/status per cycle; joint_states only for a cycle with a joint to publish (a
    # cycle that left every joint out, which a busy machine can cause, says why on ~/status
    # alone): the same stamps, each joint_states with its ~/status
    stamp = lambda m: (m.header.stamp.sec, m.header.stamp.nanosec)  # noqa: E731
    js_stamps = [stamp(m) for topic, m in decoded if topic == js]
    status = [m for topic, m in decoded if topic == node.topic("~/status")]
    assert mcap_counts[js] > 30 and len(js_stamps) == mcap_counts[js]
    assert set(js_stamps) <= {stamp(m) for m in status}
    assert len(js_stamps) == sum(any(ch.published for ch in m.channels) for m in status)
    assert any(e.kind == "write_register" and e.success and "0x000004D2" in e.request
               for e in events), [e.request for e in events]

    frames = list(can.LogReader(str(bag / "can_0.log")))
    syncs = sum(1 for fr in frames if fr.arbitration_id == SYNC_COB_ID)
    assert syncs >= mcap_counts[js], "every published cycle had its SYNC on the wire"
    ids = {fr.arbitration_id for fr in frames}
    # both directions: the gateway's TPDO1 (0x180 + node 1) and the master's RPDO1 carrying the
    # process output image of the register handshake (0x200 + node 1), docs/canopen.md
    assert {0x181, 0x201} <= ids, sorted(hex(i) for i in ids)
