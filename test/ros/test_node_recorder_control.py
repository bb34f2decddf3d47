"""Recorder control as rosbag2's recorder names it (#25 item 2): ``~/pause_recording``,
``~/resume_recording``, ``~/split_recording`` and ``is_paused`` on the bus status; and a
finalized managed node refusing ``~/start_recording`` (#24 item 7)."""

from __future__ import annotations

import time
from pathlib import Path

import yaml
from diagnostic_msgs.msg import DiagnosticArray
from lifecycle_msgs.msg import State, Transition
from mcap.reader import make_reader
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosbags.highlevel import AnyReader
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from ssi_bridge_msgs.srv import StartRecording, StopRecording

from support.lifecycle import change_state as _change
from support.lifecycle import lifecycle_state as _state
from support.lifecycle import start_managed as _start_managed

RATE = 100.0
#: a cycle latched this long before the resume was asked for has ended before it, loaded or not
PAUSE_MARGIN_NS = 300_000_000
BUS = "/ssi_bridge: bus"


def ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def bus_value(diags: list, key: str) -> str | None:
    for _, arr in reversed(diags):
        for st in arr.status:
            if st.name == BUS:
                return {kv.key: kv.value for kv in st.values}.get(key)
    return None


def test_pause_leaves_a_gap_and_split_gives_two_readable_files(running, probe, tmp_path):
    node = running({"publish_rate": RATE, "record.root": str(tmp_path / "rec"),
                    "diagnostics_period": 0.2})
    call = lambda name: probe.call(Trigger, node.topic(name), Trigger.Request())  # noqa: E731
    refused = call("~/pause_recording")
    assert not refused.success and "no recording is running" in refused.message
    received = probe.subscribe(JointState, node.topic("joint_states"), qos=QoSProfile(
        depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    start = probe.call(StartRecording, node.topic("~/start_recording"),
                       StartRecording.Request(path="ctl"))
    assert start.success, start.message
    time.sleep(1.0)

    paused = call("~/pause_recording")
    assert paused.success and "paused" in paused.message, paused.message
    paused_at = time.time_ns()  # the pause took effect before the service answered
    probe.wait_for(lambda: bus_value(diags, "is_paused") == "True", 5.0, "is_paused True", node)
    time.sleep(1.0)
    assert call("~/pause_recording").success  # a second pause changes nothing
    resume_at = time.time_ns()
    resumed = call("~/resume_recording")
    assert resumed.success and "resumed" in resumed.message, resumed.message
    probe.wait_for(lambda: bus_value(diags, "is_paused") == "False", 5.0, "is_paused False",
                   node)
    time.sleep(0.5)
    split = call("~/split_recording")
    assert split.success and split.message.endswith("ctl_1.mcap"), split.message
    assert (tmp_path / "rec" / "ctl" / "ctl_1.mcap").exists(), "the split starts the file at once"
    time.sleep(0.5)
    stop = probe.call(StopRecording, node.topic("~/stop_recording"), StopRecording.Request())
    assert stop.success, stop.message
    bag = Path(stop.bag_directory)

    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["relative_file_paths"] == ["ctl_0.mcap", "ctl_1.mcap"]
    for f in meta["files"]:  # each file stands alone
        with open(bag / f["path"], "rb") as fh:
            assert sum(1 for _ in make_reader(fh).iter_messages()) == f["message_count"] > 0
    with AnyReader([bag]) as r:
        recorded = [ns(r.deserialize(raw, c.msgtype).header.stamp) for c, _, raw in r.messages()
                    if c.topic.endswith("joint_states")]
    counts = {t["topic_metadata"]["name"]: t["message_count"]
              for t in meta["topics_with_message_count"]}
    assert counts[node.topic("joint_states")] == len(recorded), "rosbags reads the whole bag"
    # by stamp, not by when this probe took them (a loaded probe reads seconds late): a cycle
    # latched after the pause answered is never recorded; one latched before the resume was
    # asked for is, only if its cycle ended after the resume, so a margin of PAUSE_MARGIN_NS
    probe.wait_for(lambda: any(ns(m.header.stamp) >= resume_at for _, m in received), 30.0,
                   "joint_states stamped after the resume", node)
    in_pause = {t for t in (ns(m.header.stamp) for _, m in received)
                if paused_at < t < resume_at - PAUSE_MARGIN_NS}
    assert in_pause and not in_pause & set(recorded), "messages during the pause are absent"
    # the pause is the gap in the bag around the messages received while paused, a second or
    # more; a loaded machine may stall the cycle elsewhere too (a gap of a second was seen),
    # but a stall publishes nothing, so every message received outside the pause must be in
    # the bag
    around = [g for g in zip(recorded, recorded[1:])
              if g[0] < min(in_pause) and max(in_pause) < g[1]]
    assert len(around) == 1, "the messages received while paused fall in one gap of the bag"
    pause = around[0]
    assert pause[1] - pause[0] >= 0.9e9, pause
    first, last = recorded[0], recorded[-1]
    seen = [ns(m.header.stamp) for _, m in received]
    others = {t for t in seen if first <= t <= last and not pause[0] < t < pause[1]}
    assert others <= set(recorded), f"{len(others - set(recorded))} messages outside the pause lost"


def test_a_finalized_managed_node_refuses_to_record(tmp_path, domain_id, child_preexec, probe):
    root = tmp_path / "rec"
    node = _start_managed(tmp_path, domain_id, child_preexec, {"record.root": str(root)})
    try:
        probe.wait_for(lambda: "managed node: unconfigured" in node.log(), 30.0,
                       "the node's start", node)
        assert _change(probe, node, Transition.TRANSITION_CONFIGURE), node.log()
        assert _change(probe, node, Transition.TRANSITION_ACTIVATE), node.log()
        assert _change(probe, node, Transition.TRANSITION_ACTIVE_SHUTDOWN), node.log()
        assert _state(probe, node) == State.PRIMARY_STATE_FINALIZED
        res = probe.call(StartRecording, node.topic("~/start_recording"),
                         StartRecording.Request(path="late"))
        assert not res.success and "finalized" in res.message, res.message
        assert not (root / "late").exists(), "no empty bag"
    finally:
        code = node.stop()
    assert code == 0, node.log()[-3000:]


def test_recorder_control_and_snapshot_reach_the_live_view(running, probe, tmp_path):
    """The four Trigger services are offered by the live view (Foxglove's Service Call panel)
    and answer as over DDS."""
    from support.liveview import LiveViewClient, free_port, session

    port = free_port()
    node = running({"foxglove.port": port, "record.root": str(tmp_path / "rec"),
                    "record.snapshot.duration": 1.0})
    srv = node.topic("~/pause_recording").rsplit("/", 1)[0]
    names = ("pause_recording", "resume_recording", "split_recording", "snapshot")

    async def body(client: LiveViewClient) -> dict:
        out = {"types": {n: client.services[f"{srv}/{n}"]["type"] for n in names}}
        out["pause"] = await client.call(f"{srv}/pause_recording", {})
        out["snapshot"] = await client.call(f"{srv}/snapshot", {})
        return out

    fox = session(port, body)
    assert set(fox["types"].values()) == {"std_srvs/srv/Trigger"}, fox["types"]
    ros_pause = probe.call(Trigger, node.topic("~/pause_recording"), Trigger.Request())
    assert (fox["pause"].success, fox["pause"].message) == (ros_pause.success, ros_pause.message)
    assert not ros_pause.success and "no recording is running" in ros_pause.message
    assert fox["snapshot"].success and "snapshot_" in fox["snapshot"].message, fox["snapshot"]
