"""A lost CAN interface comes back by itself: the node never exits and says what happened.

The node (``simulation.enabled: false``) masters a separately started ``station`` over an interface
the test unplugs and plugs back (``unpluggable_can.py``: python-can's ``can.interface``
entry point, registered by a throwaway ``*.dist-info`` on the node's PYTHONPATH; unplugged,
its calls fail with ENETDOWN as socketcan's do and opening it fails with ENODEV). Measured on
the node's own stamps: bus ERROR with the OS reason and the joint STALE within 0.5 s of the
unplug; fresh positions within 2 s of the return; the process alive; the log quiet. Before:
every SYNC raised, the cycle thread logged a traceback per cycle, the joints never went STALE
and nothing reopened the bus.
"""

from __future__ import annotations

import math
import os
import shutil
import signal
import time
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState

from ssi_bridge.base.udp_bus import derive_channel

from support.stations import ready as _ready
from support.stations import start_station as _start_station

from .unpluggable_can import FLAG_ENV, INTERFACE

HERE = Path(__file__).resolve().parent
PERIOD = 0.5
BUS, JOINT = "/ssi_bridge: bus", "/ssi_bridge: joint1"


def _plugin_path(site: Path) -> Path:
    """A directory holding the test interface and a dist-info registering it with python-can."""
    dist = site / "ssi_test_unpluggable-0.0.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: ssi-test-unpluggable\n"
                                   "Version: 0.0\n")
    (dist / "entry_points.txt").write_text(
        f"[can.interface]\n{INTERFACE} = unpluggable_can:UnpluggableBus\n")
    shutil.copy(HERE / "unpluggable_can.py", site / "unpluggable_can.py")
    return site


def _stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def _first(diags, since: float, name: str, ok) -> tuple[float, object] | None:
    """(node stamp, status) of the first DiagnosticArray stamped after ``since`` whose status
    ``name`` satisfies ``ok``."""
    for _t, arr in list(diags):
        if _stamp(arr) < since:
            continue
        for st in arr.status:
            if st.name == name and ok(st):
                return _stamp(arr), st
    return None


def _values(st) -> dict[str, str]:
    return {kv.key: kv.value for kv in st.values}


def test_an_unplugged_interface_comes_back_without_a_restart(
        tmp_path, domain_id, probe, start_node, monkeypatch):
    site = _plugin_path(tmp_path / "site")
    flag = tmp_path / "unplugged"
    monkeypatch.setenv("PYTHONPATH", f"{site}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    monkeypatch.setenv(FLAG_ENV, str(flag))
    channel = derive_channel(f"unplug_{domain_id}_{os.getpid()}")
    station = _start_station(tmp_path, {"joints": ["joint1"], "bus.interface": "udp_multicast",
                                        "bus.channel": channel,
                                        "storage_path": str(tmp_path / "st" / "bank.json")})
    try:
        _ready(station)
        node = start_node({"simulation.enabled": False, "bus.interface": INTERFACE,
                           "bus.channel": channel, "diagnostics_period": PERIOD})
        diags = probe.subscribe(DiagnosticArray, "/diagnostics")
        joints = probe.subscribe(JointState, node.topic("joint_states"))
        probe.wait_for(lambda: _first(diags, 0, BUS, lambda st: st.level
                                      == DiagnosticStatus.OK) is not None
                       and len(joints) > 20, 30.0, "bus OK and joint_states", node)
        for cycle in range(2):  # twice: the second loss is handled as the first
            flag.touch()
            unplugged = time.time()
            probe.wait_for(lambda: _first(diags, unplugged, JOINT, lambda st: st.level
                                          == DiagnosticStatus.STALE) is not None
                           and _first(diags, unplugged, BUS, lambda st: st.level
                                      == DiagnosticStatus.ERROR) is not None,
                           10.0, "bus ERROR and joint1 STALE", node)
            at, bus = _first(diags, unplugged, BUS, lambda st: st.level == DiagnosticStatus.ERROR)
            assert "Network is down" in bus.message, bus.message
            stale_at, _ = _first(diags, unplugged, JOINT,
                                 lambda st: st.level == DiagnosticStatus.STALE)
            print(f"loss {cycle}: bus ERROR after {at - unplugged:.3f} s, joint STALE after "
                  f"{stale_at - unplugged:.3f} s: {bus.message}")
            assert at - unplugged < 0.5 and stale_at - unplugged < 0.5
            time.sleep(1.5)  # a few reopen attempts fail (ENODEV) meanwhile
            # a STALE joint's last value goes on being published, stamped with each cycle:
            # a fresh position is one that moved (the station's joint turns at 0.25 rad/s)
            frozen = joints[-1][1].position[0]
            flag.unlink()
            back = time.time()

            def fresh_positions() -> list[float]:
                return [_stamp(m) for _t, m in list(joints) if _stamp(m) > back
                        and math.isfinite(m.position[0]) and m.position[0] != frozen]
            probe.wait_for(lambda: bool(fresh_positions()), 10.0,
                           "fresh joint_states after the interface came back", node)
            fresh = fresh_positions()[0]
            print(f"loss {cycle}: fresh positions {fresh - back:.3f} s after the return")
            assert fresh - back < 2.0
            probe.wait_for(lambda: _first(diags, fresh, BUS, lambda st: st.level
                                          == DiagnosticStatus.OK) is not None
                           and _first(diags, fresh, JOINT, lambda st: st.level
                                      == DiagnosticStatus.OK) is not None,
                           2 * PERIOD + 5, "bus and joint1 OK again", node)
        assert node.proc.poll() is None
        # configured again after each return: the station answers the SYNC before the
        # re-configuration ends (it never lost its NMT state), so that may come a status later
        def configured_again(st) -> bool:
            return (st.level == DiagnosticStatus.OK
                    and int(_values(st).get("configurations", "0")) >= 3)
        probe.wait_for(lambda: _first(diags, fresh, BUS, configured_again) is not None,
                       2 * PERIOD + 5, "the station configured again after each return", node)
        _at, bus = _first(diags, fresh, BUS, configured_again)
        values = _values(bus)
        assert values["interface_losses"] == "2" and values["interface_reopens"] == "2", values
        log = node.log()
        assert "Traceback" not in log, log[-3000:]
        assert log.count("lost: [Errno 100]") == 2, log[-3000:]
        assert log.count("open again after") == 2, log[-3000:]
        assert len(log.splitlines()) < 60, log[-3000:]
    finally:
        if station.poll() is None:
            station.send_signal(signal.SIGINT)
            station.wait(10)
