"""``qos_overrides.<topic>.publisher.*`` from a params file, as rclcpp drivers take them.

The node creates ``joint_states``, ``~/status`` and ``/diagnostics`` with rclpy's
``QoSOverridingOptions.with_default_policies()``: reliability, durability, history and depth
are read-only parameters a params file sets. What DDS discovery reports of the publisher
(``get_publishers_info_by_topic``) is the overridden profile, and a recording offers that
profile in both of its copies (MCAP channel metadata and metadata.yaml): rosbags drops a
topic whose two copies differ, so it must read every message.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import yaml
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.srv import StopRecording


def _params_file(tmp_path: Path, overrides: dict) -> Path:
    path = tmp_path / "qos.yaml"
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"qos_overrides": overrides}}}))
    return path


def _publisher(probe, node, topic: str):
    """The bridge's publisher of ``topic`` as discovery reports it (None until discovered)."""
    infos = [i for i in probe.node.get_publishers_info_by_topic(topic)
             if i.node_name == "ssi_bridge"]
    return infos[0] if infos else None


def test_qos_overrides_from_a_params_file_reach_the_publishers_and_the_bag(start_node, probe,
                                                                          tmp_path: Path):
    from rosbags.highlevel import AnyReader

    root = tmp_path / "rec"
    pfile = _params_file(tmp_path, {
        "/joint_states": {"publisher": {"reliability": "best_effort", "depth": 5}},
        "/ssi_bridge/status": {"publisher": {"durability": "transient_local"}},
        "/diagnostics": {"publisher": {"reliability": "best_effort"}}})
    node = start_node({"record.enabled": True, "record.root": str(root),
                       "record.path": "session"}, params_file=pfile)
    js_topic, status_topic = node.topic("joint_states"), node.topic("~/status")
    assert status_topic == "/ssi_bridge/status"
    probe.wait_for(lambda: all(_publisher(probe, node, t) for t in
                               (js_topic, status_topic, "/diagnostics")),
                   30.0, "the three publishers in discovery", node)
    assert _publisher(probe, node, js_topic).qos_profile.reliability \
        == ReliabilityPolicy.BEST_EFFORT
    assert _publisher(probe, node, "/diagnostics").qos_profile.reliability \
        == ReliabilityPolicy.BEST_EFFORT
    status = _publisher(probe, node, status_topic).qos_profile
    assert status.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert status.reliability == ReliabilityPolicy.RELIABLE, "only what is overridden changes"

    # a best-effort subscriber hears the best-effort publisher
    msgs = probe.subscribe(JointState, js_topic,
                           QoSProfile(depth=50, reliability=ReliabilityPolicy.BEST_EFFORT))
    probe.wait_for(lambda: len(msgs) > 20, 20.0, "best-effort joint_states", node)
    stop = probe.call(StopRecording, node.topic("~/stop_recording"), StopRecording.Request())
    assert stop.success, stop.message

    bag = Path(stop.bag_directory)
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    offered = {t["topic_metadata"]["name"]: t["topic_metadata"]["offered_qos_profiles"]
               for t in meta["topics_with_message_count"]}
    assert offered[js_topic][0]["reliability"] == "best_effort"
    assert offered[js_topic][0]["depth"] == 5
    assert offered[status_topic][0]["durability"] == "transient_local"
    with AnyReader([bag]) as reader:
        counts = Counter(c.topic for c, _, _ in reader.messages())
    recorded = {t["topic_metadata"]["name"]: t["message_count"]
                for t in meta["topics_with_message_count"]}
    assert counts[js_topic] > 0 and counts[js_topic] == recorded[js_topic], (counts, recorded)
    assert counts[status_topic] == recorded[status_topic]
