"""What the installed node prints: a warning-free default, typos
named with the closest parameter, echoed input kept short, library
messages (canopen, python-can) under the node's logger. EMCY floods summarised and a silent
listen-only bus reported run in process: test/client/test_inprocess_emcy_flood.py,
test/ros/test_observe_silence.py (docs/testing.md)."""

from __future__ import annotations

import re
import signal
from pathlib import Path

import pytest

from ssi_bridge.sim.line.timing import recommended_bit_rate
from ssi_bridge.protocol.para1 import Para1
from ssi_bridge.ros.params import DEFAULT_PARA1, JointSettings

REPO = Path(__file__).resolve().parents[2]
LINE = re.compile(r"^\[(DEBUG|INFO|WARN|ERROR|FATAL)\] \[[0-9.]+\] \[([^\]]+)\]: (.*)$")


def stop(node) -> str:
    """SIGINT, exit 0; the whole log."""
    node.proc.send_signal(signal.SIGINT)
    code = node.proc.wait(30)
    log = node.log()
    assert code == 0, log[-3000:]
    return log


def lines(log: str) -> list[tuple[str, str, str]]:
    """(severity, logger, message) of every ROS log line."""
    return [m.groups() for m in map(LINE.match, log.splitlines()) if m]


def test_default_parameters_follow_the_cable_table():
    # 004 §2.7: < 400 kHz for cables under 50 m; the default cable is 10 m
    rate = Para1.decode(DEFAULT_PARA1).bit_rate_hz
    limit = recommended_bit_rate(JointSettings("j", 1).cable_length)
    assert limit is not None and rate < limit, (rate, limit)


@pytest.mark.parametrize("params_file", [None, REPO / "config" / "ssi_bridge.yaml"],
                         ids=["defaults", "shipped_config"])
def test_a_default_start_and_stop_print_no_warning_and_no_doubled_names(start_node,
                                                                         params_file):
    node = start_node(params_file=params_file)
    node.wait_for_log("bridging")
    log = stop(node)
    parsed = lines(log)
    assert parsed, log
    assert [p for p in parsed if p[0] != "INFO"] == [], log
    # one joint at 100 Hz fits 500 kbit/s (from test_node_time.py's wire-rate test, merged)
    assert "does not fit the CAN wire" not in log
    # logger names: the module is the logger, never repeated in brackets inside the message
    assert not [p for p in parsed if p[2].startswith("[")], log
    assert any(name == "ssi_bridge.client.master" for _, name, _ in parsed), log
    assert "Failed to publish log message to rosout" not in log
    assert all(LINE.match(line) for line in log.splitlines() if line.strip()), log


#: QoS overrides of no publisher of the node: a misspelt topic, policy, and a topic it has no
#: override for (from test_node_qos.py, merged here: one start with every kind of typo)
MISSPELT_QOS = {"/joint_state": {"publisher": {"reliability": "best_effort"}},
                "/joint_states": {"publisher": {"reliabilty": "best_effort"}},
                "/ssi_bridge/events": {"publisher": {"depth": 3}}}


def test_unknown_overrides_are_warned_with_the_closest_name(start_node, tmp_path: Path):
    import yaml

    pfile = tmp_path / "qos.yaml"
    pfile.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"qos_overrides": MISSPELT_QOS}}}))
    node = start_node({"publish_rte": 50.0, "joint2.slot": 2, "bus.bitrte": 250000},
                      params_file=pfile)
    node.wait_for_log("bridging")
    log = stop(node)
    warnings = [m for sev, _, m in lines(log) if sev == "WARN"]
    assert any("'publish_rte'" in w and "did you mean 'publish_rate'" in w for w in warnings), log
    assert any("'bus.bitrte'" in w and "did you mean 'bus.bitrate'" in w for w in warnings), log
    assert any("'joint2.slot'" in w and "'joint2' is not in joints ['joint1']" in w
               for w in warnings), log
    named = [w for w in warnings if "is no QoS override of this node" not in w]
    assert len(named) == 3, warnings
    for name in ("qos_overrides./joint_state.publisher.reliability",
                 "qos_overrides./joint_states.publisher.reliabilty",
                 "qos_overrides./ssi_bridge/events.publisher.depth"):
        assert f"parameter '{name}' is no QoS override of this node" in log, log[-3000:]
    assert "it takes qos_overrides.</joint_states | /ssi_bridge/status | /diagnostics>" \
        ".publisher.<history | depth | reliability | durability>" in log


def test_a_huge_joint_name_is_not_echoed_in_full(start_node):
    name = "j" * 1_000_000
    node = start_node({"joints": [name]})
    node.wait_for_log("bridging")
    log = stop(node)
    assert len(log) < 20_000, f"{len(log)} characters of log"
    assert "(1000000 characters)" in log


def test_canopen_and_python_can_messages_go_through_the_node_logger(start_node):
    node = start_node({"publish_rate": 10.0}, args=("--log-level", "debug"))
    node.wait_for_log("bridging")
    log = stop(node)
    names = {name for _, name, _ in lines(log)}
    assert {"ssi_bridge.canopen.network", "ssi_bridge.canopen.nmt"} <= names, sorted(names)
    assert not [n for n in names if n.startswith(("canopen", "can."))], sorted(names)
