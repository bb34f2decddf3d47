"""One master, several XN-GW-CANOPEN stations on one bus (docs/node.md, Stations), in process:
two simulated stations on the virtual bus (node 1 with two encoders, node 3 with one) behind
one master. Every joint publishes its own motion, a register write reaches only the joint's
station, a silent station (its heartbeat stops, CiA 301) makes only its own joints stale, EMCY
is kept per station, and the bus carries one SYNC per cycle for both stations (CiA 301: one
SYNC producer per network).

Moved from test/ros/test_node_stations.py (docs/testing.md): its ``virtual`` transport cases
(both stations in the node's process, as here); the node keeps the ``udp_multicast`` cases
(one station child process each) and the shipped two-station config's start.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticStatus as D

from ssi_bridge.base.timebase import wire_now
from ssi_bridge.protocol.settings import BusConfig, load_params_file
from ssi_bridge.sim.gateway.bus import open_bus
from ssi_bridge.sim.gateway.simulation import FaultKind as K
from support.stations import assert_own_motion

PERIOD = 0.5
SYNC_COB_ID = 0x080
#: rev/s and start (rev) of each joint's simulated constant motion
MOTION = {"a": (0.05, 1.0), "b": (-0.1, 2.0), "c": (0.2, 3.0)}
STATION = {"a": 1, "b": 1, "c": 3}
SLOT = {"a": 1, "b": 2, "c": 1}
#: a writable register no joint uses here (REG_CMP1, compare value 1; 000 Table 4)
REG = 34
RATE = 100.0
#: one count of the GENERIC encoder (8192 steps/rev) in rad
STEP = 2 * math.pi / 8192
REPO = Path(__file__).resolve().parents[2]


def _params(extra: dict | None = None) -> dict:
    params = {"joints": list(MOTION), "stations": [1, 3], "publish_rate": RATE}
    for joint, (velocity, start) in MOTION.items():
        params.update({f"{joint}.station": STATION[joint], f"{joint}.slot": SLOT[joint],
                       f"{joint}.motion.velocity": velocity, f"{joint}.motion.start": start})
    params.update(extra or {})
    return params


def _joint_of(msg, name: str):
    try:
        i = list(msg.name).index(name)
    except ValueError:
        return None
    return msg.position[i], msg.velocity[i]


def test_three_joints_on_two_stations_publish_their_own_motion(inprocess):
    t_start = time.monotonic()
    b = inprocess(_params())
    b.run_until(lambda: len(b.joint_state_msgs()) > 60, 10.0, "joint_states of both stations")
    elapsed = time.monotonic() - t_start
    assert_own_motion(b.joint_state_msgs(), MOTION, STEP, RATE, elapsed)


def test_register_write_reaches_only_the_joints_station(inprocess):
    b = inprocess(_params())
    read = lambda joint: b.bridge.read_register(b.bridge.joint(joint), REG)  # noqa: E731
    before = {j: read(j) for j in MOTION}
    value = (before["c"] + 4321) & 0xFFFFFFFF
    b.bridge.write_register(b.bridge.joint("c"), REG, value)
    after = {j: read(j) for j in MOTION}
    assert after["c"] == value
    # station 1's modules, slot 1 included (the same slot number as c's on station 3)
    assert after["a"] == before["a"] and after["b"] == before["b"]


def test_a_silent_station_stales_only_its_joints(inprocess):
    b = inprocess(_params())
    b.run_until(lambda: all(b.station_status(s).level == D.OK for s in (1, 3))
                and b.level("a") == D.OK and b.level("c") == D.OK, 5.0, "stations and joints OK")
    res = b.bridge.inject_fault(b.bridge.joint("c"), int(K.GATEWAY_SILENT), 0.0, 0.0)
    assert "station 3" in res, res
    b.run_until(lambda: b.station_status(3).level == D.ERROR, 2 * PERIOD + 1, "station 3 ERROR")
    b.run_until(lambda: b.level("c") == D.STALE, 2 * PERIOD + 1, "c STALE")
    assert "silent" in b.station_status(3).message
    time.sleep(3 * PERIOD)  # the node test waited for three diagnostics messages
    # station 1 and its joints are OK while station 3 stays silent and c STALE (a loaded
    # machine may hold back a few of station 1's SYNCs too: WARN for a moment, then OK again)
    b.run_until(lambda: b.station_status(1).level == D.OK and b.level("a") == D.OK
                and b.level("b") == D.OK, 2 * PERIOD + 3, "station 1, a and b OK")
    assert b.level("c") == D.STALE
    assert b.station_status(3).level == D.ERROR
    # station 1's joints keep moving; c has no sample latched at any stamp: left out
    k = len(b.joint_state_msgs())
    b.run_until(lambda: len(b.joint_state_msgs()) > k + 30, 5.0, "joint_states during the silence")
    window = b.joint_state_msgs()[k:]
    for name in ("a", "b"):
        seen = [_joint_of(m, name) for m in window if _joint_of(m, name) is not None]
        assert seen and seen[-1][0] != seen[0][0], f"{name} keeps moving"
    assert all(_joint_of(m, "c") is None for m in window), "c is left out while silent"
    b.bridge.inject_fault(b.bridge.joint(""), int(K.CLEAR_ALL), 0.0, 0.0)
    # back: heard again, configured again (NMT, PDOs) and fresh samples; slower when loaded
    b.run_until(lambda: b.station_status(3).level == D.OK and b.level("c") == D.OK,
                3 * PERIOD + 4, "station 3 and c OK again")


def test_one_sync_per_cycle_serves_both_stations(inprocess):
    b = inprocess(_params())
    observer = open_bus(BusConfig(interface="virtual", channel=b.bus.channel))  # another node
    try:
        first = len(b.joint_state_msgs())
        t_end = wire_now() + 1.5
        ids = []
        while wire_now() < t_end:
            frame = observer.recv(0.1)
            if frame is not None:
                ids.append(frame.arbitration_id)
        published = len(b.joint_state_msgs()) - first
    finally:
        observer.shutdown()
    sync_at = [i for i, cob in enumerate(ids) if cob == SYNC_COB_ID]
    assert len(sync_at) > 50
    # TPDO1 of each station: 0x180 + node id (CiA 301 pre-defined connection set); a station
    # answers each SYNC at most once (docs/canopen.md)
    for x, y in zip(sync_at, sync_at[1:]):
        between = ids[x + 1:y]
        assert between.count(0x181) <= 1 and between.count(0x183) <= 1, \
            [hex(i) for i in between]
    # one SYNC per published cycle, not one per station: a SYNC per station would double them
    assert published > 50
    assert len(sync_at) <= 1.5 * published + 10, (len(sync_at), published)
    answered = sum(1 for x, y in zip(sync_at, sync_at[1:])
                   if 0x181 in ids[x + 1:y] and 0x183 in ids[x + 1:y])
    assert answered > 50, "both stations answer the same SYNC"
    assert SYNC_COB_ID not in {0x80 + 1, 0x80 + 3}


def test_shipped_two_station_config(inprocess):
    with open(REPO / "config" / "ssi_bridge_two_stations.yaml") as f:
        b = inprocess(load_params_file(f))
    b.run_until(lambda: len(b.joint_state_msgs()) > 20, 10.0, "joint_states of the config")
    assert list(b.joint_state_msgs()[-1].name) == ["shoulder", "carriage", "wrist"]


def _value(status, key):
    return next(kv.value for kv in status.values if kv.key == key)


def test_emcy_is_kept_per_station(inprocess):
    # a broken data wire on c raises ERR_SSI in station 3's module -> EMCY 0x7000 from node 3
    # only (000 "Error detection / messages", CiA 301 EMCY 0x080 + node id)
    b = inprocess(_params())
    b.run_until(lambda: b.station_status(3).level == D.OK, 5.0, "station 3 OK")
    b.bridge.inject_fault(b.bridge.joint("c"), int(K.DATA_WIRE_BREAK), 0.0, 0.0)
    b.run_until(lambda: b.station_status(3).level == D.WARN, 2 * PERIOD + 1, "station 3 WARN")
    st3 = b.station_status(3)
    assert "0x7000" in st3.message and "0x7000" in _value(st3, "emcy_history"), st3
    st1 = b.station_status(1)
    assert st1.level == D.OK and _value(st1, "emcy_count") == "0", st1
    b.run_until(lambda: b.level("c") == D.ERROR, 2 * PERIOD + 1, "c ERROR")
    assert b.level("a") == D.OK, b.status("a")
