"""One node for simulated and real stations (docs/architecture.md "Three layers").

A node with ``simulation.enabled: false`` drives a separately started ``station`` program as it
would drive real hardware: it loads nothing of ``ssi_bridge.sim``, and it knows a joint only from
its parameters and the bus. So the rules that depend on the encoder are the same code as in
the simulated default: a REG_PARA1 with invalid LSB bits (000 Table 19) changes the scale of
REG_SSI_POS and joint_states follows it; a linear family (TTK70, 004 §3.6) is published in m.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.srv import WriteRegister

from ssi_bridge.base.udp_bus import derive_channel
from ssi_bridge.protocol.para1 import Para1
from ssi_bridge.protocol.registers import Reg

from .conftest import REPO, NodeProcess, dds_env, installed_executable, joint_of
from .test_node_station_process import _ready
from .test_node_station_process import _start_station as start_station_process

#: REG_PARA1 of the default joint (25-bit binary frame, 250 kbit/s) with INVALID_BITS_LSB = 2
PARA1_TWO_INVALID_LSB = 0x19020200


def _start_station(tmp_path: Path, params: dict, *args: str) -> subprocess.Popen:
    """The ``station`` program on ``params``, once it said it is ready."""
    proc = start_station_process(tmp_path, params, *args)
    _ready(proc)
    return proc


def _stop_station(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)


def _start_probed_node(tmp_path: Path, domain_id: int, params: dict,
                       modules_file: Path) -> NodeProcess:
    """The installed node executable, run by a Python that writes ``sys.modules`` at exit."""
    pfile = tmp_path / "node.yaml"
    pfile.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
    exe = installed_executable("ssi_bridge_node")
    code = ("import atexit, runpy, sys\n"
            f"atexit.register(lambda: open({str(modules_file)!r}, 'w').write("
            "'\\n'.join(sorted(sys.modules))))\n"
            f"sys.argv = [{str(exe)!r}, '--ros-args', '--params-file', {str(pfile)!r}]\n"
            f"runpy.run_path({str(exe)!r}, run_name='__main__')\n")
    log_path = tmp_path / "node.log"
    env = dds_env(domain_id)
    with open(log_path, "wb") as log:
        proc = subprocess.Popen([sys.executable, "-c", code], stdout=log,
                                stderr=subprocess.STDOUT, env=env, cwd=tmp_path,
                                start_new_session=True,
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    return NodeProcess(proc, domain_id, "", log_path, env=env)


def _sim_modules(modules_file: Path) -> list[str]:
    return [m for m in modules_file.read_text().split() if m.startswith("ssi_bridge.sim")]


def test_a_node_on_real_hardware_loads_nothing_of_the_simulator(tmp_path, domain_id, probe):
    channel = derive_channel(f"real_{domain_id}_{os.getpid()}")
    bus = {"bus.interface": "udp_multicast", "bus.channel": channel}
    station = _start_station(tmp_path, {"joints": ["joint1"], **bus,
                                        "storage_path": str(tmp_path / "st" / "bank.json")})
    modules = tmp_path / "modules_real.txt"
    node = _start_probed_node(tmp_path, domain_id, {"simulation.enabled": False, **bus}, modules)
    try:
        joints = probe.subscribe(JointState, node.topic("joint_states"))
        probe.wait_for(lambda: len(joints) > 20, 30.0, "joint_states from the station", node)
        assert node.stop() == 0, node.log()[-3000:]
    finally:
        node.stop()
        _stop_station(station)
    assert modules.exists(), node.log()[-3000:]
    assert "ssi_bridge.client.master" in modules.read_text().split()  # the probe saw the node
    assert _sim_modules(modules) == [], "a node on real hardware loaded the simulator"


def test_the_simulated_default_loads_the_supervisor(tmp_path, domain_id, probe):
    """The control of the probe above: with simulation.enabled: true the supervisor is loaded."""
    modules = tmp_path / "modules_sim.txt"
    node = _start_probed_node(tmp_path, domain_id, {
        "bus.channel": f"probe_{domain_id}", "storage_path": str(tmp_path / "bank.json")},
        modules)
    try:
        joints = probe.subscribe(JointState, node.topic("joint_states"))
        probe.wait_for(lambda: len(joints) > 5, 30.0, "joint_states", node)
        assert node.stop() == 0, node.log()[-3000:]
    finally:
        node.stop()
    assert "ssi_bridge.sim.supervisor" in _sim_modules(modules)


def _position_after(joints: list, since: float) -> float:
    return next(m.position[0] for t, m in joints if t > since)


def _invalid_lsb_keeps_the_position(node: NodeProcess, probe) -> None:
    joints = probe.subscribe(JointState, node.topic("joint_states"))
    probe.wait_for(lambda: len(joints) > 20, 30.0, "joint_states", node)
    before = joints[-1][1].position[0]
    assert math.isfinite(before)
    res = probe.call(WriteRegister, node.topic("~/write_register"), WriteRegister.Request(
        joint="joint1", address=int(Reg.REG_PARA1), value=PARA1_TWO_INVALID_LSB))
    assert res.success, res.message
    written = time.monotonic()
    probe.wait_for(lambda: any(t > written + 0.3 and math.isfinite(m.position[0])
                               for t, m in joints), 10.0, "joint_states after the write", node)
    after = next(m.position[0] for t, m in joints
                 if t > written + 0.3 and math.isfinite(m.position[0]))
    # GENERIC: 8192 steps per revolution; two invalid LSB bits leave 2048 counts per turn
    lsb = Para1.decode(PARA1_TWO_INVALID_LSB).invalid_bits_lsb
    count = 2 * math.pi / (8192 / 2 ** lsb)
    assert abs(after - before) <= count, (
        f"position moved from {before} to {after} rad when REG_PARA1 dropped {lsb} LSB bits "
        f"(one count of the new resolution: {count:.6f} rad)")


def test_invalid_lsb_bits_keep_the_position_on_a_real_station(tmp_path, domain_id, probe,
                                                               start_node):
    """000 Table 19 INVALID_BITS_LSB shifts REG_SSI_POS right: the node's scale follows."""
    channel = derive_channel(f"lsb_{domain_id}_{os.getpid()}")
    bus = {"bus.interface": "udp_multicast", "bus.channel": channel}
    still = {"joint1.motion.kind": "still", "joint1.motion.start": 0.3}
    station = _start_station(tmp_path, {"joints": ["joint1"], **bus, **still,
                                        "storage_path": str(tmp_path / "st" / "bank.json")})
    try:
        node = start_node({"simulation.enabled": False, **bus})
        _invalid_lsb_keeps_the_position(node, probe)
    finally:
        _stop_station(station)


def test_invalid_lsb_bits_keep_the_position_on_the_simulated_default(probe, start_node):
    node = start_node({"joint1.motion.kind": "still", "joint1.motion.start": 0.3})
    _invalid_lsb_keeps_the_position(node, probe)


@pytest.mark.parametrize("simulation", [False, True])
def test_the_readme_station_commands_publish_the_linear_joint_in_metres(
        tmp_path, domain_id, probe, start_node, simulation):
    """README "The simulated station on its own": config/ssi_bridge.yaml's TTK70 carriage
    moves at 0.01 m/s; published in m and m/s whether the node or the station program runs
    the simulation."""
    config = REPO / "config" / "ssi_bridge.yaml"
    channel = derive_channel(f"readme_{domain_id}_{os.getpid()}")
    bus = {"bus.interface": "udp_multicast", "bus.channel": channel}
    station = None
    if not simulation:
        station = subprocess.Popen(
            [str(installed_executable("station")), "--params-file", str(config),
             "--interface", "udp_multicast", "--channel", channel],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
        _ready(station)
    try:
        node = start_node({"simulation.enabled": simulation, **(bus if not simulation else {})},
                          params_file=config)
        joints = probe.subscribe(JointState, node.topic("joint_states"))
        probe.wait_for(lambda: len(joints) > 150, 30.0, "joint_states", node)
        carriage = [(m, v) for _, m in joints[-100:]
                    if (v := joint_of(m, "carriage")) is not None]
        velocities = [v for _m, (_p, v) in carriage if math.isfinite(v)]
        assert velocities, "no finite carriage velocity"
        mean = sum(velocities) / len(velocities)
        assert abs(mean - 0.01) < 0.001, f"carriage at {mean} (m/s expected: 0.01)"
        # between samples with a finite velocity (a left-out stretch restarts the estimate)
        fresh = [(m, pv) for m, pv in carriage if math.isfinite(pv[1])]
        span = fresh[-1][0].header.stamp.sec + fresh[-1][0].header.stamp.nanosec * 1e-9 - (
            fresh[0][0].header.stamp.sec + fresh[0][0].header.stamp.nanosec * 1e-9)
        moved = fresh[-1][1][0] - fresh[0][1][0]
        # metres, not radians (the bug this guards against was a factor of ~700): within 10 %
        # of the motion, which a station process starved beside burners keeps (7 % seen)
        assert abs(moved - 0.01 * span) < 0.001 * span, f"carriage moved {moved} m in {span:.2f} s"
    finally:
        if station is not None:
            _stop_station(station)
