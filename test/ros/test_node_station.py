"""Two bridges side by side in namespaces, each with its own station and joints.

The shipped two-encoder params file and the accuracy of position and velocity against the
simulated ground truth (docs/node.md) run in process: test/core/test_inprocess_station.py
(docs/testing.md)."""

from __future__ import annotations

import math
import time

import pytest
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.srv import ReadRegister


def _collect(probe, node, seconds, topic="joint_states"):
    msgs = probe.subscribe(JointState, node.topic(topic))
    probe.wait_for(lambda: len(msgs) > 3, 10.0, "joint_states", node)
    start = len(msgs)
    time.sleep(seconds)
    return [m for _, m in msgs[start:]]


def test_two_bridges_side_by_side_in_namespaces(running, probe):
    # (joint names "y"/"n"/"on" would be YAML 1.1 booleans in a params file)
    a = running({"joints": ["lift"], "lift.motion.velocity": 0.25}, namespace="/station_a")
    b = running({"joints": ["turn"], "turn.motion.velocity": -0.5,
                 "turn.motion.start": 100.0}, namespace="/station_b")
    ma = _collect(probe, a, 1.0)
    mb = _collect(probe, b, 1.0)
    assert {tuple(m.name) for m in ma} == {("lift",)}
    assert {tuple(m.name) for m in mb} == {("turn",)}
    assert ma[-1].velocity[0] == pytest.approx(2 * math.pi * 0.25, rel=0.02)
    assert mb[-1].velocity[0] == pytest.approx(2 * math.pi * -0.5, rel=0.02)
    for node in (a, b):
        res = probe.call(ReadRegister, node.topic("~/read_register"),
                         ReadRegister.Request(address=1))
        assert res.success and res.value == 0xAA55CC33


RATE = 100.0
STEP = 2 * math.pi / 8192  # rad per count of the default 13-bit single-turn resolution
