"""The managed node (ssi_bridge_managed_node) driven through the standard lifecycle services.

States and transitions are ROS 2's managed-node design (lifecycle_msgs): configure opens the
bus (the simulated station is started), activate starts the SYNC cycle and publishing,
deactivate stops publishing with the bus still open, cleanup closes the bus and stops the
station's child process, shutdown ends in finalized.
"""

from __future__ import annotations

import os
import re
import time
from pathlib import Path

import pytest
from lifecycle_msgs.msg import State, Transition
from sensor_msgs.msg import JointState

from support.lifecycle import RATE
from support.lifecycle import change_state as _change
from support.lifecycle import lifecycle_state as _state
from support.lifecycle import start_managed as _start_managed
from support.ros_process import NodeProcess


def _station_pid(node: NodeProcess, probe) -> int:
    probe.wait_for(lambda: "simulated station up as process" in node.log(), 10.0,
                   "the station's start line", node)
    return int(re.findall(r"simulated station up as process (\d+)", node.log())[-1])


def _quiet_for(msgs: list, seconds: float) -> int:
    """How many joint_states arrived during ``seconds`` (a window, not a timed bound)."""
    before = len(msgs)
    time.sleep(seconds)
    return len(msgs) - before


def _bus_sockets(pid: int, log: str) -> int:
    """How many sockets process ``pid`` holds bound to the node's udp_multicast bus port
    (the port its log names), from /proc/net/udp* and /proc/<pid>/fd."""
    port = int(re.findall(r"udp_multicast:[0-9.]+:(\d+)", log)[-1])
    inodes = set()
    for table in ("/proc/net/udp", "/proc/net/udp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            fields = line.split()
            if int(fields[1].rsplit(":", 1)[1], 16) == port:
                inodes.add(f"socket:[{fields[9]}]")
    held = 0
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            held += os.readlink(fd) in inodes
        except OSError:  # closed meanwhile
            pass
    return held


def test_walk_through_the_lifecycle(tmp_path, domain_id, child_preexec, probe):
    """With fault snapshots of the CAN frames (a listener of its own on the bus), so that
    cleanup is seen to close every socket of the node on the bus, not the master's alone."""
    node = _start_managed(tmp_path, domain_id, child_preexec, {
        "record.root": str(tmp_path / "rec"), "record.snapshot.duration": 2.0,
        "record.can_log": True})
    try:
        msgs = probe.subscribe(JointState, node.topic("joint_states"))
        probe.wait_for(lambda: "managed node: unconfigured" in node.log(), 30.0,
                       "the node's start", node)
        assert _state(probe, node) == State.PRIMARY_STATE_UNCONFIGURED
        assert "simulated station up" not in node.log(), "unconfigured must open nothing"

        assert _change(probe, node, Transition.TRANSITION_CONFIGURE), node.log()
        assert _state(probe, node) == State.PRIMARY_STATE_INACTIVE
        pid = _station_pid(node, probe)
        assert Path(f"/proc/{pid}").exists(), "configure starts the simulated station"
        assert _bus_sockets(node.proc.pid, node.log()) >= 2, "the master and the snapshots' tap"
        assert _quiet_for(msgs, 1.0) == 0, "inactive: no joint_states"

        for _ in range(2):  # active -> inactive -> active again
            assert _change(probe, node, Transition.TRANSITION_ACTIVATE), node.log()
            assert _state(probe, node) == State.PRIMARY_STATE_ACTIVE
            start = len(msgs)
            probe.wait_for(lambda: len(msgs) >= start + 10, 20.0, "joint_states while active",
                           node)
            assert _change(probe, node, Transition.TRANSITION_DEACTIVATE), node.log()
            assert _state(probe, node) == State.PRIMARY_STATE_INACTIVE
            time.sleep(0.3)  # messages already in flight when the cycle stopped
            assert _quiet_for(msgs, 1.0) == 0, "inactive: no joint_states"
            assert Path(f"/proc/{pid}").exists(), "deactivate keeps the bus (and station)"

        assert _change(probe, node, Transition.TRANSITION_CLEANUP), node.log()
        assert _state(probe, node) == State.PRIMARY_STATE_UNCONFIGURED
        probe.wait_for(lambda: not Path(f"/proc/{pid}").exists(), 10.0,
                       "the station process to end after cleanup", node)
        assert "cleaned up: bus closed" in node.log()
        assert _bus_sockets(node.proc.pid, node.log()) == 0, "cleanup leaves no socket on the bus"

        # configure again opens a new bus side; activate publishes again
        assert _change(probe, node, Transition.TRANSITION_CONFIGURE), node.log()
        pid2 = _station_pid(node, probe)
        assert pid2 != pid
        assert _bus_sockets(node.proc.pid, node.log()) >= 2, "configure opens the tap again"
        assert _change(probe, node, Transition.TRANSITION_ACTIVATE), node.log()
        start = len(msgs)
        probe.wait_for(lambda: len(msgs) >= start + 10, 20.0, "joint_states after reconfigure",
                       node)

        assert _change(probe, node, Transition.TRANSITION_ACTIVE_SHUTDOWN), node.log()
        assert _state(probe, node) == State.PRIMARY_STATE_FINALIZED
        probe.wait_for(lambda: not Path(f"/proc/{pid2}").exists(), 10.0,
                       "the station process to end after shutdown", node)
        assert _quiet_for(msgs, 0.5) <= 1
    finally:
        code = node.stop()
    assert code == 0, node.log()[-3000:]


def test_failing_configure_stays_unconfigured(tmp_path, domain_id, child_preexec, probe):
    # no simulated station and nothing else on the bus: the gateway never answers
    node = _start_managed(tmp_path, domain_id, child_preexec, {"simulation.enabled": False})
    try:
        probe.wait_for(lambda: "managed node: unconfigured" in node.log(), 30.0,
                       "the node's start", node)
        assert not _change(probe, node, Transition.TRANSITION_CONFIGURE)
        assert _state(probe, node) == State.PRIMARY_STATE_UNCONFIGURED
        assert "configure failed:" in node.log()
        assert node.proc.poll() is None, "a failed transition does not end the process"
    finally:
        code = node.stop()
    assert code == 0, node.log()[-3000:]


@pytest.mark.parametrize("executable", ["ssi_bridge_node", "managed_autostart"])
def test_an_autostarting_node_is_active_at_once_and_still_managed(
        executable, running, tmp_path, domain_id, child_preexec, probe):
    """One node class: ssi_bridge_node configures and activates itself at start (autostart),
    and so does the managed node given ``autostart: true``; a lifecycle manager can still
    deactivate and activate either. (Two tests before, one per executable.)"""
    if executable == "ssi_bridge_node":
        node = running({"publish_rate": RATE})
    else:
        node = _start_managed(tmp_path, domain_id, child_preexec, {"autostart": True})
    try:
        msgs = probe.subscribe(JointState, node.topic("joint_states"))
        probe.wait_for(lambda: len(msgs) >= 10, 30.0, "joint_states without a transition",
                       node)
        assert _state(probe, node) == State.PRIMARY_STATE_ACTIVE
        assert "managed node: unconfigured" not in node.log()
        assert _change(probe, node, Transition.TRANSITION_DEACTIVATE), node.log()
        assert _state(probe, node) == State.PRIMARY_STATE_INACTIVE
        time.sleep(0.3)  # messages already in flight when the cycle stopped
        assert _quiet_for(msgs, 1.0) == 0, "inactive: no joint_states"
        assert _change(probe, node, Transition.TRANSITION_ACTIVATE), node.log()
        start = len(msgs)
        probe.wait_for(lambda: len(msgs) >= start + 10, 20.0, "joint_states after activate",
                       node)
    finally:
        code = node.stop()
    assert code == 0, node.log()[-3000:]
