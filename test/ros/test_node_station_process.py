"""The simulated station as its own device: a child process of the node, reached over CAN only.

Checks the life cycle a user relies on: the child dies with the node (also after ``kill -9``),
a crashed station is an ERROR in the bus diagnostics while the node keeps publishing, the
``station`` program runs on its own and a node with ``simulation.enabled:=false`` drives it as real
hardware, and the in-process ``virtual`` fallback still reaches the station only by bus.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.msg import Status
from ssi_bridge_msgs.srv import InjectFault, ReadRegister, WriteRegister

from ssi_bridge.base.udp_bus import derive_channel
from ssi_bridge.base.realtime import fifo_permitted, thread_policies

from support.stations import children as _children
from support.stations import gone as _gone
from support.stations import ready as _ready
from support.stations import start_station as _start_station
from support.stations import station_of as _station_of

from .conftest import dds_env, installed_executable

REG_LOWER_LIMIT = 48
PERIOD = 0.5
#: the station as a child process of the node
CHILD = {"simulation.transport": "udp_multicast"}


def _wait(predicate, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.02)


def _bus_status(diags):
    for _, arr in reversed(diags):
        for st in arr.status:
            if st.name == "/ssi_bridge: bus":
                return st
    return None


@pytest.mark.parametrize("how", ["kill_9", "clean_stop"])
def test_the_station_child_ends_with_its_node(running, how):
    """kill -9 of the node leaves no station behind (the child dies with its parent); a clean
    stop of the node (exit 0) stops the station. (Two tests of the same node before.)"""
    node = running(CHILD)
    station = _station_of(node)
    assert not _gone(station)
    if how == "kill_9":
        os.kill(node.proc.pid, signal.SIGKILL)
        node.proc.wait(10)
        _wait(lambda: _gone(station), 10.0, f"station process {station} to end after kill -9 "
              "of the node")
    else:
        assert node.stop() == 0
        _wait(lambda: _gone(station), 10.0, "station process to end with the node")


def test_a_crashed_station_is_a_bus_error_and_the_node_keeps_publishing(running, probe):
    """No sample can be vouched for once the station is gone: joint_states stops (no value
    under a stamp it was not latched at), while ~/status says why every cycle and the
    diagnostics go on."""
    node = running({"diagnostics_period": PERIOD, **CHILD})
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    joints = probe.subscribe(JointState, node.topic("joint_states"))
    status = probe.subscribe(Status, node.topic("~/status"))
    probe.wait_for(lambda: (st := _bus_status(diags)) is not None
                   and st.level == DiagnosticStatus.OK, 10.0, "bus OK", node)
    killed = time.time()  # the node stamps with the system clock (ROS time)
    os.kill(_station_of(node), signal.SIGKILL)
    probe.wait_for(lambda: (st := _bus_status(diags)) is not None
                   and st.level == DiagnosticStatus.ERROR
                   and "simulated station process exited" in st.message,
                   2 * PERIOD + 3, "bus ERROR naming the ended station", node)
    before, n = len(status), len(diags)
    probe.wait_for(lambda: len(status) > before + 10, 5.0, "~/status after the crash", node)
    probe.wait_for(lambda: len(diags) > n + 2, 5.0, "/diagnostics after the crash", node)
    # judged by the cycle's stamp, not by arrival: on a busy machine ~/status of cycles from
    # before the kill can still be on their way when the bus ERROR is seen. A SYNC sent 0.1 s
    # after the kill has no station left to answer it
    after = [m for _, m in status
             if m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec > killed + 0.1]
    assert len(after) > 10, f"only {len(after)} ~/status stamped after the kill"
    reasons = {ch.set_aside_reason for m in after for ch in m.channels}
    assert reasons == {"no answer"}, reasons
    assert all(not ch.published for m in after for ch in m.channels)
    last = len(joints)
    time.sleep(0.5)
    assert len(joints) == last, "no joint_states without a sample latched at its stamp"
    assert node.proc.poll() is None


def test_faults_reach_the_child_station_over_the_bus(running, probe):
    node = running({"diagnostics_period": PERIOD, **CHILD})
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")

    def level(name):
        for _, arr in reversed(diags):
            for st in arr.status:
                if st.name == name:
                    return st.level
        return None
    K = InjectFault.Request
    probe.wait_for(lambda: level("/ssi_bridge: joint1") == DiagnosticStatus.OK, 10.0,
                   "joint1 OK", node)
    res = probe.call(InjectFault, node.topic("~/inject_fault"),
                     K(kind=K.DATA_WIRE_BREAK, duration=1.0))
    assert res.success and "for 1 s" in res.message, res.message
    probe.wait_for(lambda: level("/ssi_bridge: joint1") == DiagnosticStatus.ERROR,
                   2 * PERIOD + 2, "joint1 ERROR from the wire break", node)
    probe.wait_for(lambda: level("/ssi_bridge: joint1") == DiagnosticStatus.OK,
                   1.0 + 2 * PERIOD + 3, "joint1 OK once the station ended the fault", node)
    res = probe.call(InjectFault, node.topic("~/inject_fault"), K(kind=K.GATEWAY_SILENT))
    assert res.success, res.message
    probe.wait_for(lambda: level("/ssi_bridge: bus") == DiagnosticStatus.ERROR,
                   2 * PERIOD + 2, "bus ERROR while the station is silent", node)
    refused = probe.call(InjectFault, node.topic("~/inject_fault"), K(kind=K.ENCODER_ERROR))
    assert not refused.success and "only CLEAR_ALL" in refused.message, refused.message
    res = probe.call(InjectFault, node.topic("~/inject_fault"), K(kind=K.CLEAR_ALL))
    assert res.success, res.message  # the silent station applied the clear, then answered
    probe.wait_for(lambda: level("/ssi_bridge: bus") == DiagnosticStatus.OK,
                   3 * PERIOD + 3, "bus OK with the heartbeat back", node)


def test_a_station_that_cannot_start_is_one_line_and_exit_1(start_node, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    node = start_node({"storage_path": str(blocker / "sub" / "bank.json"),
                       "simulation.start_timeout": 20.0, **CHILD})
    assert node.proc.wait(60) == 1, node.log()
    lines = [ln for ln in node.log().splitlines() if "cannot start" in ln]
    assert len(lines) == 1 and "simulated station" in lines[0] and "exited" in lines[0], \
        node.log()


def test_virtual_fallback_runs_in_process_and_faults_still_go_over_the_bus(running, probe):
    node = running({"simulation.transport": "virtual", "diagnostics_period": PERIOD})
    assert not [k for k in _children(node.proc.pid)
                if b"ssi_bridge.sim.program" in Path(f"/proc/{k}/cmdline").read_bytes()]
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    res = probe.call(InjectFault, node.topic("~/inject_fault"),
                     InjectFault.Request(kind=InjectFault.Request.DATA_WIRE_BREAK))
    assert res.success, res.message

    def joint_level():
        for _, arr in reversed(diags):
            for st in arr.status:
                if st.name == "/ssi_bridge: joint1":
                    return st.level
        return None
    probe.wait_for(lambda: joint_level() == DiagnosticStatus.ERROR, 2 * PERIOD + 2,
                   "joint1 ERROR from the injected wire break", node)


def test_without_multicast_on_loopback_the_default_names_the_fallback(tmp_path, domain_id):
    """A fresh network namespace has its loopback down: no multicast, so no station child."""
    ns = f"ssibnomc{os.getpid() % 100000}"
    if shutil.which("ip") is None:
        pytest.skip("the `ip` tool (iproute2) is not installed")
    made = subprocess.run(["ip", "netns", "add", ns], capture_output=True, text=True)
    if made.returncode != 0:
        pytest.skip(f"`ip netns add` not permitted here: {made.stderr.strip()}")
    try:
        out = subprocess.run(
            ["ip", "netns", "exec", ns, str(installed_executable("ssi_bridge_node")),
             "--ros-args", "-p", f"storage_path:={tmp_path / 'bank.json'}"],
            capture_output=True, text=True, timeout=120, env=dds_env(domain_id))
    finally:
        subprocess.run(["ip", "netns", "del", ns], capture_output=True)
    text = out.stdout + out.stderr
    assert out.returncode == 1, text
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1 and "cannot start" in lines[0], text
    assert "simulation.transport:=virtual" in lines[0], text


def test_node_with_simulation_false_drives_a_separately_started_station(
        start_node, probe, tmp_path, domain_id):
    channel = derive_channel(f"standalone_{domain_id}_{os.getpid()}")
    bus = {"bus.interface": "udp_multicast", "bus.channel": channel}
    station = _start_station(tmp_path, {"joints": ["joint1"], **bus,
                                        "storage_path": str(tmp_path / "st" / "bank.json")})
    try:
        _ready(station)
        node = start_node({"simulation.enabled": False, **bus})
        joints = probe.subscribe(JointState, node.topic("joint_states"))
        probe.wait_for(lambda: len(joints) > 20, 30.0, "joint_states from the station", node)
        w = probe.call(WriteRegister, node.topic("~/write_register"),
                       WriteRegister.Request(address=REG_LOWER_LIMIT, value=1234))
        assert w.success, w.message
        r = probe.call(ReadRegister, node.topic("~/read_register"),
                       ReadRegister.Request(address=REG_LOWER_LIMIT))
        assert r.success and r.value == 1234, r.message
        assert node.stop() == 0
    finally:
        station.send_signal(signal.SIGINT)
        code = station.wait(10)
    assert code == 0, station.stderr.read().decode()[-2000:]


def test_station_help_is_plain_text():
    out = subprocess.run([str(installed_executable("station")), "--help"], capture_output=True, text=True,
                         env=dds_env(0), timeout=30)
    assert out.returncode == 0
    for word in ("--params-file", "udp_multicast", "simulation.enabled:=false", "0x4000"):
        assert word in out.stdout
    for markup in ("``", ":param", ":class:", ".. "):
        assert markup not in out.stdout, markup


def test_station_bad_parameters_exit_2_in_one_line(tmp_path):
    station = _start_station(tmp_path, {"joints": ["a"], "a.motion.kind": "wobble"})
    assert station.wait(30) == 2
    err = station.stderr.read().decode().strip().splitlines()
    assert len(err) == 1 and "a.motion.kind" in err[0], err


def test_the_station_child_runs_at_its_priority_or_says_why_not(running):
    """simulation.station_priority (docs/node.md): SCHED_FIFO 10 for every thread of the child,
    or, without the right to it, normal scheduling and one INFO line saying so; 0: normal."""
    node = running(CHILD)
    station = _station_of(node)
    if fifo_permitted(10):
        assert thread_policies(station) == {(os.SCHED_FIFO, 10)}, thread_policies(station)
    else:
        assert thread_policies(station) == {(os.SCHED_OTHER, 0)}
        assert "SCHED_FIFO 10 not permitted" in node.log()
    assert node.stop() == 0
    node = running({**CHILD, "simulation.station_priority": 0})
    assert thread_policies(_station_of(node)) == {(os.SCHED_OTHER, 0)}
    assert "simulated station runs with normal scheduling" not in node.log()
