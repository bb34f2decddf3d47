"""The node held to the truth under disturbance: what the truth tests and bench share.

:class:`Run` starts nothing itself: it takes a running node (``test/ros/conftest.py``'s
fixtures start it) and a probe, subscribes to ``joint_states``, ``~/status`` and
``/diagnostics``, reads each station's motion epoch (object 0x4004) and the node's stated
bound (``latch_bound_s`` on the bus status), and holds every published sample against the
truth oracle (:mod:`support.truth`). The disturbances are what real buses do to a master:
a stalled station, frame loss, another node's NMT commands and SYNCs, error frames.
Test-side only; uses rclpy through the tests' probe.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.msg import Status
from ssi_bridge_msgs.srv import InjectFault, SdoRead

from ssi_bridge.base.udp_bus import open_udp_bus
from support.stations import children
from support.truth import TruthOracle, flatten, samples_from_joint_states
from support.virtual_bus import send_syncs

K = InjectFault.Request
RATE = 200.0
#: bench/bench_truth.py sets this: each case appends its figures there as a JSON line
REPORT_ENV = "SSI_BRIDGE_TRUTH_REPORT"
SIM_EPOCH = 0x4004  # simulation only: the station's motion epoch, UNSIGNED64 us
REPO = Path(__file__).resolve().parents[2]


def latest_status(diags: list[tuple[float, Any]], name: str) -> Any:
    """The newest DiagnosticStatus called ``name`` among received arrays, or None."""
    for _, arr in reversed(diags):
        for st in arr.status:
            if st.name == name:
                return st
    return None


def station_pids(node: Any) -> list[int]:
    """The pids of a node's simulated station children (one per station on udp_multicast)."""
    return [k for k in children(node.proc.pid)
            if b"ssi_bridge.sim.program" in Path(f"/proc/{k}/cmdline").read_bytes()]


def station_pid(node: Any) -> int:
    """The pid of a node's one simulated station child."""
    stations = station_pids(node)
    assert len(stations) == 1, f"expected one station child of the node, got {stations}"
    return stations[0]


def params(channel: str, **extra: Any) -> dict[str, Any]:
    """One joint at 200 Hz on ``channel``."""
    return {"joints": ["joint1"], "publish_rate": RATE, "bus.channel": channel,
            "diagnostics_period": 0.25, **extra}


def epochs(probe, node, stations: list[int]) -> dict[int, float]:
    """Each station's motion epoch (wire time, s) from object 0x4004 over ~/sdo_read."""
    out = {}
    for sid in stations:
        for _attempt in range(5):  # a station being (re)configured may miss one SDO timeout
            res = probe.call(SdoRead, node.topic("~/sdo_read"), SdoRead.Request(
                node_id=sid, index=SIM_EPOCH, subindex=0, data_type="UNSIGNED64"))
            if res.success:
                break
            time.sleep(0.5)
        assert res.success, res.message
        out[sid] = res.unsigned_value / 1e6
    return out


def bus_values(diags) -> dict[str, str]:
    st = latest_status(diags, "/ssi_bridge: bus")
    return {kv.key: kv.value for kv in st.values} if st is not None else {}


class Run:
    """A node with subscriptions, its oracle and its stated bound."""

    def __init__(self, running: Callable[..., Any], probe, params: dict[str, Any]) -> None:
        self.probe, self.params = probe, params
        self.node = running(params)
        self.diags = probe.subscribe(DiagnosticArray, "/diagnostics")
        self.joints = probe.subscribe(JointState, self.node.topic("joint_states"), qos=2000)
        self.status = probe.subscribe(Status, self.node.topic("~/status"), qos=2000)
        names = list(params.get("joints", ["joint1"]))
        self.first = names[0]
        for name in names:
            probe.wait_for(lambda n=name: (st := latest_status(self.diags, f"/ssi_bridge: {n}"))
                           is not None and st.level == DiagnosticStatus.OK, 20.0,
                           f"{name} OK", self.node)
        stations = sorted({int(params.get(f"{n}.station", 0)) or int(params.get("bus.node_id", 1))
                           for n in names})
        self.oracle = TruthOracle.from_params(params, epochs(probe, self.node, stations))
        probe.wait_for(lambda: "latch_bound_s" in bus_values(self.diags), 5.0,
                       "latch_bound_s on the bus status", self.node)
        self.bound = float(bus_values(self.diags)["latch_bound_s"])
        #: (wire time, name) of each disturbance started
        self.phases: list[tuple[float, str]] = []

    def check(self, case: str = "", t0: float | None = None) -> None:
        """Every sample the node stamped until now holds the rule (received first:
        :meth:`received_until`); it is a failure listing the worst.

        ``case``/``t0``: the disturbance's name and start (monotonic), for the bench's figures.
        """
        self.received_until(time.time())
        self.hold(self.samples(), self.oracle, case, t0)

    def samples(self) -> list[Any]:
        """Every sample received so far, velocities NaN where this probe missed part of the
        node's window (:meth:`_seen_whole`)."""
        return self._seen_whole(samples_from_joint_states(m for _, m in self.joints))

    def hold(self, samples: list[Any], oracle: TruthOracle, case: str = "",
             t0: float | None = None) -> None:
        """``samples`` hold the rule against ``oracle``; a failure lists the worst (see
        :meth:`check`)."""
        report = oracle.check(samples, self.bound)
        self._report(case, t0, report)
        dump = os.environ.get("SSI_BRIDGE_TRUTH_DUMP")
        if dump and not report.ok:
            with open(dump, "a", encoding="utf-8") as out:
                for sm in samples:
                    out.write(json.dumps([case, sm.stamp, sm.joint, sm.position, sm.velocity,
                                          oracle.residual(sm.joint, sm.stamp, sm.position),
                                          oracle.velocity(sm.joint, sm.stamp)]) + "\n")
                for v in report.violations:
                    out.write(json.dumps(["VIOLATION", case, v.stamp, v.joint, v.kind,
                                          v.velocity_error, v.bound]) + "\n")
        assert report.checked > 0
        assert report.ok, report.summary() + self._phases_of(report)

    def _seen_whole(self, samples: list[Any]) -> list[Any]:
        """``samples`` with the velocity unknown (NaN) where this probe cannot know the window
        the node used: a message it missed (a loaded machine's subscriber falls behind the
        publisher's history) would make it take a longer window than the node's. Each
        ~/status channel counts the joint's published samples (``samples``): a velocity is
        checked only where the last ``velocity_window`` samples were all received."""
        count = {(round(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, 6), ch.joint):
                 ch.samples for _, m in self.status for ch in m.channels if ch.published}
        window = self.oracle.velocity_window
        out: list[Any] = []
        series: dict[str, list[int | None]] = {}
        for sm in sorted(samples, key=lambda x: x.stamp):
            seen = series.setdefault(sm.joint, [])
            seen.append(count.get((round(sm.stamp, 6), sm.joint)))
            last = seen[-window:]
            whole = (len(last) == window and None not in last
                     and all(b - a == 1 for a, b in zip(last, last[1:])))  # type: ignore[operator]
            out.append(sm if whole else dataclasses.replace(sm, velocity=math.nan))
        return out

    def phase(self, name: str) -> None:
        """A disturbance starts now (wire time), for the failure message."""
        self.phases.append((time.time(), name))

    def _phases_of(self, report: Any) -> str:
        if not self.phases:  # a case that named no phase: nothing to say where they fell
            return ""

        def of(stamp: float) -> str:
            return next((f"{name} +{stamp - t:.3f} s" for t, name in reversed(self.phases)
                         if t <= stamp), "before any disturbance")
        return "".join(f"\n    {v.joint} {v.kind} {v.residual_counts:+.0f} counts: {of(v.stamp)}"
                       for v in report.violations[:40])

    def _report(self, case: str, t0: float | None, report: Any) -> None:
        path = os.environ.get(REPORT_ENV)
        if not path or not case:
            return
        after = self.diagnostics_after(t0) if t0 is not None else None
        set_aside = max((ch.set_aside for _, m in self.status for ch in m.channels),
                        default=0)
        left_out = sum(1 for _, m in self.status for ch in m.channels if not ch.published)
        with open(path, "a", encoding="utf-8") as out:
            out.write(json.dumps({
                "case": case, "checked": report.checked,
                "worst_residual_counts": report.worst_residual_counts,
                "worst_velocity_error": report.worst_velocity_error,
                "violations": len(report.violations), "set_aside": set_aside,
                "left_out_cycles": left_out,
                "diagnostics_after_s": after,
                "latch_bound_s": self.bound}) + "\n")

    def diagnostics_after(self, t0: float) -> float | None:
        """Seconds from the first cycle after ``t0`` (monotonic) that left the first joint out
        to the first /diagnostics message with that joint or the bus not OK, both by the
        node's own stamps (so neither DDS nor this process's scheduling counts); None when no
        cycle left it out."""
        def stamp(m: Any) -> float:
            return m.header.stamp.sec + m.header.stamp.nanosec * 1e-9

        w0 = time.time() - (time.monotonic() - t0)
        out = [stamp(m) for _, m in self.status if stamp(m) >= w0
               for ch in m.channels if ch.joint == self.first and not ch.published]
        if not out:
            return None
        first = min(out)
        said = [stamp(arr) for _, arr in self.diags if stamp(arr) >= first
                for st in arr.status
                if st.name in (f"/ssi_bridge: {self.first}", "/ssi_bridge: bus")
                and st.level > DiagnosticStatus.OK]
        return (min(said) - first) if said else None

    def set_aside_during(self, w0: float, w1: float) -> set[str]:
        """The reasons ~/status gave for the first joint left out of the cycles stamped in
        [w0, w1] (wire time, ``time.time()``)."""
        return {ch.set_aside_reason for _, m in self.status
                if w0 <= m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 <= w1
                for ch in m.channels if ch.joint == self.first and not ch.published}

    def worst_level_during(self, t0: float, t1: float) -> int:
        levels = [st.level for t, arr in self.diags if t0 <= t <= t1 for st in arr.status
                  if st.name == f"/ssi_bridge: {self.first}"]
        return max(levels, default=DiagnosticStatus.OK)

    def published_again(self, after: float) -> None:
        """The node publishes the first joint again: a joint_states stamped after ``after``
        (monotonic) is received. By its stamp, not by when it arrived: a probe starved
        beside burners receives seconds late, and a message it receives after ``after`` may
        be one the node published before it."""
        wire = time.time() - (time.monotonic() - after)
        self.probe.wait_for(lambda: _newest(self.joints, self.first) > wire, 30.0,
                            "joint_states stamped after the disturbance", self.node)

    def received_until(self, wire: float, timeout: float = 30.0) -> None:
        """Wait until the probe has received a joint_states with the first joint and a
        ~/status stamped at or after ``wire`` (wire time): each topic's messages arrive in
        the order published (one reliable writer each), so then every one stamped before
        ``wire`` is in. A check of "every sample stamped so far" waits here first: a probe
        on a busy machine falls seconds behind the node's 200 Hz (its executor handles every
        message in Python), and a check right after a disturbance would miss samples the
        node did publish."""
        self.probe.wait_for(lambda: _newest(self.joints, self.first) >= wire
                            and _newest(self.status, "") >= wire, timeout,
                            f"joint_states and ~/status stamped at or after {wire:.3f}",
                            self.node)


def _newest(received: list[tuple[float, Any]], joint: str) -> float:
    """The newest stamp (wire time) among ``received`` messages (with ``joint`` among their
    names, unless empty); -inf before any. Scans from the newest received: they arrive in
    stamp order."""
    for _, msg in reversed(received):
        if not joint or joint in msg.name:
            return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
    return -math.inf


def foreign_syncs(wire: str, rate: float, seconds: float, stop: threading.Event) -> int:
    """Send SYNC (0x080) at ``rate`` Hz for ``seconds`` from another producer on ``wire``."""
    return send_syncs(open_udp_bus(wire), rate, seconds, stop)


def two_stations(channel: str) -> dict[str, Any]:
    """The shipped two-station example (AFM60 sine, TTK70 linear, GENERIC on a second
    station), on this test's bus."""
    doc = yaml.safe_load((REPO / "config" / "ssi_bridge_two_stations.yaml").read_text())
    params = flatten(doc["/**"]["ros__parameters"])
    params.update({"bus.channel": channel, "publish_rate": RATE, "diagnostics_period": 0.25,
                   "simulation.transport": "udp_multicast"})
    return params


def eight_joints(channel: str) -> dict[str, Any]:
    """Eight encoders on one station: rotary and linear, constant, reversed and sine."""
    names = [f"j{k}" for k in range(1, 9)]
    params: dict[str, Any] = {"joints": names, "publish_rate": RATE, "bus.channel": channel,
                              "diagnostics_period": 0.25}
    for k, name in enumerate(names, start=1):
        params[f"{name}.slot"] = k
        if k % 4 == 0:
            params.update({f"{name}.motion.kind": "sine", f"{name}.motion.amplitude": 0.3,
                           f"{name}.motion.frequency": 0.5})
        elif k % 4 == 1:
            params[f"{name}.motion.velocity"] = 0.1 * k
        elif k % 4 == 2:
            params.update({f"{name}.direction": -1, f"{name}.motion.velocity": 0.3})
        else:
            params.update({f"{name}.family": "TTK70", f"{name}.para1": 0x1A020200,
                           f"{name}.motion.velocity": 0.05})
    return params


def _nmt(wire: str, command: int, node_id: int) -> None:
    """One NMT command from another node on the bus (CiA 301 §7.2.8.3.1)."""
    bus = open_udp_bus(wire)
    try:
        bus.send(can.Message(arbitration_id=0x000, data=[command, node_id],
                             is_extended_id=False))
    finally:
        bus.shutdown()


def _set_rate(probe, node, rate: float) -> None:
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    res = probe.call(SetParameters, node.topic("~/set_parameters"), SetParameters.Request(
        parameters=[Parameter(name="publish_rate", value=ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE, double_value=rate))]))
    assert res.results[0].successful, res.results[0].reason


def _inject(probe, node, **fields: Any) -> None:
    """``~/inject_fault`` given the time a loaded machine's service queue may need."""
    res = probe.call(InjectFault, node.topic("~/inject_fault"), K(**fields), timeout=30.0)
    assert res.success, res.message


def matrix(run: Run, wire: str, node_id: int) -> None:
    """Stalls, frame loss, NMT commands of another node, error frames, foreign SYNCs and a
    publish_rate change, one after the other, each followed by a recovery. Each phase's
    start (wire time) goes to ``run.phases``, so a violation names the phase it fell in."""
    probe, node = run.probe, run.node
    phase = run.phase
    station = station_pids(node)[0]  # the first station's process (node id order)
    for seconds in (0.1, 0.5):
        phase(f"stall {seconds} s")
        os.kill(station, signal.SIGSTOP)
        time.sleep(seconds)
        os.kill(station, signal.SIGCONT)
        run.published_again(time.monotonic() + 0.3)
    for rate in (0.01, 0.5):
        phase(f"frame loss {rate}")
        _inject(probe, node, kind=K.CAN_FRAME_LOSS, rate=rate, duration=1.5)
        time.sleep(2.0)
    for command in (0x02, 0x82, 0x80):  # stop, reset communication, pre-operational
        phase(f"NMT 0x{command:02X} from another node")
        _nmt(wire, command, node_id)
        time.sleep(1.5)
        run.published_again(time.monotonic())
    for kind in (K.ERROR_PASSIVE, K.BUS_OFF):
        phase(f"error frames {kind}")
        _inject(probe, node, kind=kind, duration=1.0)
        time.sleep(2.5)
        run.published_again(time.monotonic())
    stop = threading.Event()
    phase("foreign SYNC 10 Hz")
    foreign_syncs(wire, 10.0, 1.0, stop)
    phase("foreign SYNC 1 kHz")
    foreign_syncs(wire, 1000.0, 1.0, stop)
    run.published_again(time.monotonic() + 0.5)
    phase("publish_rate 500 Hz")
    _set_rate(probe, node, 500.0)
    time.sleep(1.0)
    phase("publish_rate back")
    _set_rate(probe, node, RATE)
    time.sleep(1.0)
