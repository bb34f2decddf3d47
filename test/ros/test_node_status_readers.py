"""``~/status`` is built only while it has a reader (ros/cycle_publish.py), its readers
counted once per ``STATUS_READERS_EVERY_S`` of cycles: a reader that comes while the node
runs gets ``~/status`` promptly, and every cycle's from then on."""

from __future__ import annotations

import time
from typing import Any

from ssi_bridge_msgs.msg import Status

from ssi_bridge.ros.cycle_publish import STATUS_READERS_EVERY_S

RATE = 500.0


def test_a_status_reader_that_comes_later_gets_every_cycle_promptly(running, probe) -> None:
    node = running({"joints": ["j"], "publish_rate": RATE})
    received: list[tuple[float, Any]] = []
    sub = probe.node.create_subscription(
        Status, node.topic("~/status"), lambda m: received.append((time.monotonic(), m)), 200)
    probe._subscriptions.append(sub)
    probe.wait_for(lambda: sub.get_publisher_count() > 0, 10.0, "~/status discovered", node)
    matched = time.monotonic()  # the reader's side has matched the node's writer
    probe.wait_for(lambda: len(received) > 0, 5.0, "the first ~/status", node)
    # the node's side matches about when this side does (DDS discovery both ways, one
    # process each on localhost); the count is read again within STATUS_READERS_EVERY_S
    # (50 cycles here): far less than the margin a loaded machine needs
    assert received[0][0] - matched < STATUS_READERS_EVERY_S + 0.45, received[0][0] - matched
    from sensor_msgs.msg import JointState

    states = probe.subscribe(JointState, node.topic("joint_states"), 200)
    time.sleep(1.0)
    # every cycle's ~/status from then on: each joint_states (a cycle published) has the
    # ~/status of the same stamp (a slot skipped on a loaded machine has neither)
    both = [m.header.stamp for _, m in states[5:-5]]
    status = {(m.header.stamp.sec, m.header.stamp.nanosec) for _, m in received}
    assert len(both) > 0.2 * RATE, len(both)
    missing = [s for s in both if (s.sec, s.nanosec) not in status]
    assert not missing, f"{len(missing)} of {len(both)} cycles without ~/status"
