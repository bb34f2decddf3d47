"""The installed ``commission`` executable writes a params file the node starts with.

A ``station`` program (the simulated station as a process of its own, as a real one would be)
holds an AFM60 multiturn encoder in Gray code (004 §3.2: 12 + 15 position bits + 3 error bits,
30 clocks) turning at a known speed; its REG_PARA1 is what a previous set-up left. The tool
reads the bus and writes ``station.yaml``; the node started with that file alone (plus the
bus channel the test gives every node) publishes the joint in rad/s at the speed the station
really turns: the units follow from the family and resolution the tool found.
"""

from __future__ import annotations

import math
import os
import statistics
import subprocess
from pathlib import Path

import canopen
from sensor_msgs.msg import JointState

from ssi_bridge.base.buses import open_python_can
from ssi_bridge.base.udp_bus import derive_channel
from ssi_bridge.commission.discover import ENCODER_CONFIG
from ssi_bridge.protocol.para1 import Para1
from ssi_bridge.protocol.settings import BusConfig

from support.ros_process import installed_executable
from support.stations import started_station as start_station
from support.stations import stop_station

NODE_ID = 7
#: rev/s of the simulated shaft (not the 0.25 of a node's own simulated default station)
SPEED = 0.4
#: 30-bit Gray frame at 250 kbit/s (000 Table 19)
PARA1 = Para1(ssi_frame_len=30, ssi_bit_rate=2, ssi_code_gray=True).encode()


def _station(tmp_path: Path, channel: str) -> subprocess.Popen:
    return start_station(tmp_path, {
        "joints": ["shaft"], "shaft.family": "AFM60_MULTI", "shaft.code": "gray",
        "shaft.steps_per_rev": 32768, "shaft.motion.kind": "constant",
        "shaft.motion.velocity": SPEED, "shaft.motion.start": 10.0,
        "bus.interface": "udp_multicast", "bus.channel": channel, "bus.node_id": NODE_ID})


def _leave_para1(channel: str) -> None:
    """REG_PARA1 as a previous set-up left it (object 0x5801, 000 Table 16)."""
    network = canopen.Network(open_python_can(BusConfig("udp_multicast", channel)))
    network.connect()
    try:
        node = network.add_node(NODE_ID, canopen.ObjectDictionary())
        node.sdo.download(ENCODER_CONFIG, 1, PARA1.to_bytes(4, "little"))
    finally:
        network.disconnect()


def test_the_node_runs_from_the_generated_file_in_the_right_units(tmp_path, start_node,
                                                                 probe):
    channel = derive_channel(f"commission-node-{os.getpid()}-{tmp_path.name}")
    station = _station(tmp_path, channel)
    try:
        _leave_para1(channel)
        out_file = tmp_path / "commissioned.yaml"
        done = subprocess.run([str(installed_executable("commission")), "--interface",
                               "udp_multicast", "--channel", channel, "--node-ids", "1-20",
                               "--seconds", "2", "-o", str(out_file)],
                              capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, done.stderr[-3000:]
        assert "Traceback" not in done.stderr
        text = out_file.read_text()
        assert "family: AFM60_MULTI" in text and f"para1: 0x{PARA1:08X}" in text, text
        node = start_node({"bus.channel": channel}, params_file=out_file)
        joints = probe.subscribe(JointState, node.topic("joint_states"))
        probe.wait_for(lambda: len(joints) > 60, 30.0, "joint_states from the station", node)
        names = {tuple(m.name) for _, m in joints}
        assert names == {(f"node{NODE_ID}_slot1",)}, names
        velocity = statistics.median(m.velocity[0] for _, m in joints[10:])
        assert math.isclose(velocity, 2 * math.pi * SPEED, rel_tol=0.03), velocity
        assert node.stop() == 0
    finally:
        stop_station(station)
