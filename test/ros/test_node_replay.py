"""Log replay: a session's CAN log, recorded from a simulated node, drives a second node.

Both nodes are the installed executable in their own process on real DDS; the second runs
with ``simulation.enabled: false`` and ``replay.can_log`` and must publish what the first one did.
"""

from __future__ import annotations

import math
import statistics
from pathlib import Path

import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.srv import InjectFault, ReadRegister

#: GENERIC default encoder: 13 bits per revolution, 12 bits of revolutions (REG_SSI_POS scale)
STEPS, TURNS = 8192, 4096
SPEED = 0.25  # rev/s
STALE = 3
#: joint_states history of the nodes and the probe (qos_overrides, docs/parameters.md)
DEPTH = 1000
DEEP = {"qos_overrides./joint_states.publisher.depth": DEPTH}


def _counts(position: float) -> int:
    return round(position * STEPS / (2 * math.pi))


@pytest.fixture
def recorded_log(running, probe, tmp_path: Path) -> tuple[Path, set[int]]:
    """A ~2-3 s session with can_log from a simulated node; its log and published counts."""
    root = tmp_path / "rec"
    node = running({**DEEP, "record.enabled": True, "record.can_log": True,
                    "record.root": str(root), "record.path": "session",
                    "joint1.motion.kind": "constant", "joint1.motion.velocity": SPEED})
    # deep histories on both ends (the node's is 10 by default): a test process starved
    # beside busy neighbours must not lose messages it is asked to compare one by one
    seen = probe.subscribe(JointState, node.topic("joint_states"), qos=DEPTH)
    probe.wait_for(lambda: len(seen) >= 200, 20.0, "200 simulated joint_states", node)
    assert node.stop() == 0, node.log()[-3000:]
    log = root / "session" / "can_0.log"
    assert log.is_file() and log.stat().st_size > 0, f"no CAN log in {sorted(root.rglob('*'))}"
    return log, {_counts(m.position[0]) for _, m in seen}


def _joint_counters(diags: list[tuple[float, DiagnosticArray]]) -> dict[str, str]:
    """The last /diagnostics counters of joint1 (samples, set aside, why): whether the node
    left a cycle out or the probe missed a message."""
    for _, arr in reversed(diags):
        for st in arr.status:
            if st.name == "/ssi_bridge: joint1":
                keys = ("samples", "stale_cycles", "samples_set_aside", "left_out_because")
                return {kv.key: kv.value for kv in st.values if kv.key in keys}
    return {}


def test_replayed_log_publishes_the_recorded_positions(recorded_log, start_node, probe) -> None:
    log, simulated = recorded_log
    # the replay waits for this test's subscriber: a 2 s log must not end before discovery
    node = start_node({**DEEP, "simulation.enabled": False, "replay.can_log": str(log),
                       "joint1.steps_per_rev": STEPS, "joint1.revolutions": TURNS,
                       "bus.node_id": 1, "replay.wait_for_subscribers": 15.0})
    msgs = probe.subscribe(JointState, node.topic("joint_states"), qos=DEPTH)
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    probe.wait_for(lambda: len(msgs) >= 30, 20.0, "replayed joint_states", node)

    read = probe.call(ReadRegister, node.topic("~/read_register"),
                      ReadRegister.Request(address=0))
    assert not read.success
    assert "listen-only: another master drives this bus" in read.message, read.message
    fault = probe.call(InjectFault, node.topic("~/inject_fault"),
                       InjectFault.Request(kind=1, joint="joint1"))
    assert not fault.success and "simulation" in fault.message, fault.message

    probe.wait_for(lambda: "ended after" in node.log(), 20.0, "the end of the replay", node)
    n_at_end = len(msgs)

    def joint_stale() -> bool:
        for _, arr in diags[-5:]:
            for st in arr.status:
                level = st.level[0] if isinstance(st.level, bytes) else st.level
                if st.name == "/ssi_bridge: joint1" and level == STALE:
                    return True
        return False

    probe.wait_for(joint_stale, 10.0, "joint1 diagnostics STALE after the log ended", node)
    assert node.proc.poll() is None, "the node must keep running after the log ended"
    assert len(msgs) - n_at_end <= 2, "no joint_states without observed SYNCs"

    replayed = [m for _, m in msgs]
    counts = [_counts(m.position[0]) for m in replayed]
    # every position the simulated node published while the log plays is replayed (same
    # REG_SSI_POS, same scale). Not the other way round: on a busy machine the live node
    # leaves out a cycle whose frames its cycle thread did not see within the cycle's wait,
    # while the replay, deciding from the logged frames alone, may vouch for it
    assert len(replayed) >= 150, f"only {len(replayed)} replayed cycles"
    replayed_counts = set(counts)
    inside = [c for c in simulated if min(counts) <= c <= max(counts)]
    missing = sorted(c for c in inside if c not in replayed_counts)
    assert len(inside) >= 50 and len(missing) <= 2, (
        f"{len(missing)} of {len(inside)} recorded positions not replayed, e.g. {missing[:10]}; "
        f"the replay node's own count of joint1: {_joint_counters(diags)}")
    # the shaft turns one way at constant speed: each replayed sample is ahead of the last
    assert all(b > a for a, b in zip(counts, counts[1:])), "replayed positions out of order"
    # at the logged rate (100 Hz), stamped with the logged SYNC spacing
    stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in replayed]
    spacing = statistics.median(b - a for a, b in zip(stamps, stamps[1:]))
    assert spacing == pytest.approx(0.01, abs=0.001), spacing
    velocities = [m.velocity[0] for m in replayed[10:] if math.isfinite(m.velocity[0])]
    assert velocities, "no velocity estimate"
    assert statistics.median(velocities) == pytest.approx(2 * math.pi * SPEED, rel=0.03)
    assert node.stop() == 0


def test_replay_exits_at_the_end_when_asked_and_records_again(recorded_log, start_node,
                                                              tmp_path: Path) -> None:
    log, _ = recorded_log
    root = tmp_path / "again"
    node = start_node({"simulation.enabled": False, "replay.can_log": str(log), "replay.rate": 4.0,
                       "replay.exit_at_end": True, "record.enabled": True,
                       "record.root": str(root), "record.path": "replayed"})
    assert node.proc.wait(30) == 0, node.log()[-3000:]
    assert "exiting (replay.exit_at_end)" in node.log()
    info = yaml.safe_load((root / "replayed" / "metadata.yaml").read_text())
    counts = {t["topic_metadata"]["name"]: t["message_count"]
              for t in info["rosbag2_bagfile_information"]["topics_with_message_count"]}
    assert counts.get("/joint_states", 0) >= 150, counts
