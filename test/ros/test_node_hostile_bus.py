"""A node and its station child survive what another process puts on their CAN-over-UDP bus.

Through the installed node (default set-up: a simulated station as a child
process on udp_multicast on loopback). From the test process, loopback only: datagrams that
are not CAN frames to the group and unicast to the port, a msgpack frame with identifier
0xFFFF and DLC 15, heartbeats of node 1 with a state outside CiA 301 (§7.2.8.3.2.1), and one
NMT stop of node 1 (§7.2.8.3.1, ``0x000 [02 01]``). Before: the node exited 1 about 2 s after
the first datagram (its receive thread ended, every SYNC send failed) and its station child
died with it; the invalid heartbeat ended the supervisor thread; the NMT stop left the joints
STALE.
"""

from __future__ import annotations

import math
import os
import re
import socket
import struct
import time

import can
from can.interfaces.udp_multicast.utils import pack_message
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState

from ssi_bridge.base.udp_bus import open_udp_bus, parse_channel

from support.stations import gone as _gone
from support.stations import station_of as _station_of

from .conftest import station_channel, latest_status, wait_for_level

PERIOD = 0.5
GARBAGE = b"\xc1 this is not a CAN frame"
BAD_FRAME = pack_message(can.Message(arbitration_id=0xFFFF, is_extended_id=False, dlc=15,
                                    data=bytes(15)))  # unchecked: no CAN 2.0A frame


def _values(st) -> dict[str, str]:
    return {kv.key: kv.value for kv in st.values}


def test_the_node_survives_a_hostile_bus_and_says_what_it_saw(running, probe, domain_id):
    name = f"hostile_{domain_id}_{os.getpid()}"
    node = running({"bus.channel": name, "diagnostics_period": PERIOD})
    endpoint = parse_channel(station_channel(name, domain_id))
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    joints = probe.subscribe(JointState, node.topic("joint_states"))
    wait_for_level(probe, node, diags, "/ssi_bridge: joint1", DiagnosticStatus.OK, 20.0)
    station = _station_of(node)

    raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    raw.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
    raw.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, struct.pack("@I", 1))
    other = open_udp_bus(station_channel(name, domain_id))  # another node on the bus
    try:
        for i in range(300):
            raw.sendto(GARBAGE if i % 2 else BAD_FRAME, (endpoint.group, endpoint.port))
            raw.sendto(GARBAGE if i % 2 else BAD_FRAME, ("127.0.0.1", endpoint.port))
            if i % 3 == 0:
                other.send(can.Message(arbitration_id=0x701, data=[0x35], is_extended_id=False))
            time.sleep(0.001)
        other.send(can.Message(arbitration_id=0x000, data=[0x02, 0x01], is_extended_id=False))
        last, last_wall = time.monotonic(), time.time()
    finally:
        raw.close()
        other.shutdown()

    def fresh() -> bool:  # a position latched after the NMT stop had taken effect
        if not joints:
            return False
        msg = joints[-1][1]
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        return stamp > last_wall + 0.05 and not math.isnan(msg.position[0])

    # fresh positions within 1 s of the last injected frame, node and station alive
    probe.wait_for(fresh, 1.0 - (time.monotonic() - last), "fresh joint_states", node)
    print(f"fresh positions {time.monotonic() - last:.3f} s after the NMT stop")
    assert node.proc.poll() is None, node.log()[-3000:]
    assert not _gone(station), "the station child died"
    probe.wait_for(lambda: (st := latest_status(diags, "/ssi_bridge: bus")) is not None
                   and int(_values(st).get("nmt_restarts", 0)) >= 1
                   and int(_values(st)["undecodable_frames"]) >= 300, 2 * PERIOD + 2,
                   "the faults in the bus diagnostics", node)
    # the bus status said so: WARN naming what grew, in one of the messages meanwhile
    warned = [st.message for _t, m in diags for st in m.status
              if st.name == "/ssi_bridge: bus" and st.level == DiagnosticStatus.WARN]
    assert any("undecodable_frames" in w for w in warned), warned
    assert any("invalid_nmt_states" in w or "nmt_restarts" in w for w in warned), warned
    bus = _values(latest_status(diags, "/ssi_bridge: bus"))
    # the unicast half never reached the bus (bound to the group)
    assert int(bus["undecodable_frames"]) == 300, bus
    assert int(bus["invalid_nmt_states"]) == 100, bus
    assert int(bus["supervisor_errors"]) == 0 and int(bus["callback_errors"]) == 0, bus
    wait_for_level(probe, node, diags, "/ssi_bridge: joint1", DiagnosticStatus.OK,
                   time.monotonic() - last + 2 * PERIOD + 2)
    log = node.log()
    assert "Traceback" not in log and "Exception in thread" not in log, log[-3000:]
    for kind in ("not a CAN frame", "none of CiA 301", "started again"):
        lines = len(re.findall(kind, log))
        assert 1 <= lines < 50, (kind, lines)
