"""Benchmark: ssi_bridge_node's joint_states against a bare rclpy publisher.

For 1 and 8 encoders (joints j1..jN on slots 1..N) the installed ``ssi_bridge_node`` runs on a
simulated 1 Mbit/s CAN wire at 1 kHz (1 encoder) or at the highest rate that wire allows for
8 slots (docs/canopen.md table: 480 Hz), and a subscriber in another process (``bench/node_subscriber.py``)
records the receive wall time and ``header.stamp`` of every JointState. The same subscriber
program then measures a bare rclpy timer publisher (this file with ``--bare``) of an equally
sized JointState (same joint names, position and velocity arrays) at the same rate, in the
same run and the same DDS domain. After ~2 s of warm-up, ~5 s are measured per publisher:

* ``rate_hz``: messages received per second of the window (higher is better; goal >= 0.99x bare)
* ``jitter_p99_us``: p99 of |receive interval - 1/rate| (lower is better)
* ``latency_p50_us`` / ``latency_p99_us``: receive wall time - header.stamp; the node stamps
  the SSI latch (SYNC) time, the bare publisher the instant before publish() (lower is better;
  goal p99 <= 1.2x bare)
* ``cpu_s_per_s``: utime+stime of the publisher process (/proc/<pid>/stat) over the window per
  second; the node's is its own process (its station child, ``simulation.transport:
  udp_multicast``, is not in it; the simulated wire's timing of the node's own frames is)
  (lower is better)

The driver alone, first (``node_<N>enc_driver_*``; ``BENCH_NODE_ONLY=driver`` runs only this
part): each case :data:`DRIVER_RUNS` times in one sitting, each run the node, the bare and the
floor publisher; printed as the median of the runs' ratios, with the runs:

* ``driver_latency_p50_us`` / ``_p99_us``: the node's span per cycle, from the kernel receive
  timestamp of the frame that completed it to ``publish()`` returning (the node writes it when
  ``SSI_BRIDGE_SPAN_LOG`` names a file, ``ssi_bridge/ros/span_probe.py``), against the floor
  publisher's span, datagram in the kernel (``SO_TIMESTAMPNS``) to ``publish()`` returning
  (goal p99 <= 1.3x)
* ``driver_cpu_s_per_s``: the node's process alone against the bare publisher (goal <= 1.5x);
  ``station_child_cpu_s_per_s``: its station child process, for the record
* ``driver_real_*``: the same figures with the node as a real deployment runs it
  (``real_station.py``: ``simulation.enabled:=false`` on udp_multicast against the ``station``
  program started apart), so the node process holds the driver alone; the plain
  ``driver_*`` node has the simulation on, its own bus end the simulated wire (its SYNC paced
  at bit time in the node process)

* ``latency_beyond_wire_p50_us`` / ``_p99_us``: receive - header.stamp minus the
  computed SYNC -> last TPDO wire time (the TPDOs of one cycle, worst-case stuffed) against
  the bare publisher's latency (goal p99 <= 1.2x)
* ``latency_floor_p50_us`` / ``_p99_us``: the floor publisher (this file with ``--floor``)
  against the bare one. Another process sends a datagram stamped with its send time at the
  case rate; a thread of an rclpy node, woken by it at the node's receive-thread priority,
  publishes the same JointState stamped with that send time at once. That is the least any
  rclpy node adds that publishes data it receives from a device (its receive thread's
  wake-up, nothing else): the bridge's latency beyond the wire cannot be below it.
  ``latency_beyond_wire_vs_floor_p50_us`` / ``_p99_us``: the node's latency beyond the wire
  against the floor: what the bridge adds on top of that
* loaded run (1 encoder, 1 kHz, two CPU-burning processes beside it, killed by PID at the
  end): ``cycles_missed_fraction``, ``spurious_faults`` (EMCY / "silent" in the node log),
  ``stamp_inversions``

Live view cost (``foxglove.port``): one node with 1 encoder at 1 kHz and its Foxglove WebSocket
server on; its CPU s/s in alternating windows with no client, one client
(``bench/liveview_client.py``, another process) subscribed to joint_states, and one subscribed
to every node topic; medians of 3 rounds (``node_1enc_liveview_*``).

The subscriber runs SCHED_FIFO ``SUBSCRIBER_PRIORITY`` (3, below the node's default
``cycle_priority`` 5), as the real-time consumer of a robot (a ros2_control loop) would: a
normally scheduled subscriber that falls behind for tens of ms (starved by the node's and the
station's real-time threads waking 2-3 kHz) adds its own backlog to every publisher's
latency. Where SCHED_FIFO is not permitted it runs normally; the notes say which.

QoS on both sides is the node's: KEEP_LAST 10, RELIABLE, VOLATILE. DDS is isolated: a unique
ROS_DOMAIN_ID and ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST. Every subprocess is stopped by PID.

Prints one JSON object per line and appends them to bench/results/latest.jsonl; never fails
(an error becomes a line with "error"; exit status 0).
"""

from __future__ import annotations

import ctypes
import functools
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path
from typing import Any

from benchlib import cpu_seconds, save
from benchlib import emit_record as emit

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO / "test"))
from support.ros_process import dds_env  # noqa: E402  (the node tests' isolated DDS domain)
NODE_EXE = REPO / "install" / "ssi_bridge" / "lib" / "ssi_bridge" / "ssi_bridge_node"
SUBSCRIBER = HERE / "node_subscriber.py"
LIVEVIEW_CLIENT = HERE / "liveview_client.py"

RATE_HZ = 1000.0
CASES = (1, 8)
#: the simulated wire's bit rate of every case (docs/canopen.md rate table)
BITRATE = 1_000_000
WARMUP_S = 2.0
MEASURE_S = 5.0
STARTUP_TIMEOUT_S = 20.0
NODE_NS = "/bench_node"
BARE_TOPIC = "/bench_bare/joint_states"
#: stations case: 13 frames per cycle (SYNC + 8 image + 4 position TPDOs), about
#: 1.6 ms of wire at 1 Mbit/s with worst-case stuffing, so 400 Hz loads the wire ~65 %
STATIONS_RATE_HZ = 400.0
STATIONS_BITRATE = 1_000_000

#: the node's span probe (ssi_bridge/ros/span_probe.py): set in the measured node's environment
SPAN_ENV = "SSI_BRIDGE_SPAN_LOG"
#: runs of each case for the driver-only figures (medians of the runs' ratios)
DRIVER_RUNS = 3
#: goals of the driver-only figures (issue: the driver's own latency and CPU)
DRIVER_GOALS = {"latency_p99": 1.3, "cpu": 1.5}

UNITS = {"rate_hz": "Hz", "jitter_p99_us": "us", "latency_p50_us": "us",
         "latency_p99_us": "us", "cpu_s_per_s": "s/s"}
GOALS = {"rate_hz": (">=", 0.99), "latency_p99_us": ("<=", 1.2)}
NOTES = {
    "rate_hz": "messages received per second; higher is better",
    "jitter_p99_us": "p99 of |receive interval - 1/rate|; lower is better",
    "latency_p50_us": "receive wall time - header.stamp, median; lower is better",
    "latency_p99_us": "receive wall time - header.stamp, p99; lower is better",
    "cpu_s_per_s": "publisher process CPU s (utime+stime) per s of publishing; the node's "
                   "process alone (not its station child); lower is better",
}


# -- the bare publisher (a subprocess of this file) -------------------------------------------
def _joint_state_publisher(kind: str, topic: str) -> tuple[Any, Any]:
    """rclpy started, a node ``bench_<kind>_<pid>`` and its JointState publisher on ``topic``
    with the bridge's QoS."""
    import rclpy
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    rclpy.init(args=None)
    node = rclpy.create_node(f"bench_{kind}_{os.getpid()}")
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    return node, node.create_publisher(JointState, topic, qos)


def _joint_state(names: list[str], count: int, sec: int, nanosec: int) -> Any:
    """The benchmark's JointState: ``names``, a position that moves with ``count``, a speed."""
    from sensor_msgs.msg import JointState

    js = JointState()
    js.header.stamp.sec, js.header.stamp.nanosec = sec, nanosec
    js.name = names
    js.position = [count * 1e-3] * len(names)
    js.velocity = [1.0] * len(names)
    return js


def bare_publisher(n_joints: int, rate: float, topic: str) -> int:
    """A bare rclpy timer publishing an N-joint JointState at ``rate``; runs until SIGINT."""
    from ssi_bridge.tools.spin import spin_until_shutdown

    node, pub = _joint_state_publisher("bare", topic)
    names = [f"j{i + 1}" for i in range(n_joints)]
    clock = node.get_clock()
    count = [0]

    def tick() -> None:
        count[0] += 1
        sec, nanosec = clock.now().seconds_nanoseconds()
        pub.publish(_joint_state(names, count[0], sec, nanosec))

    node.create_timer(1.0 / rate, tick)
    spin_until_shutdown(node)
    return 0


# -- the floor publisher (a subprocess of this file) ------------------------------------------
#: the floor's receive thread runs at the node's default cycle_priority, which the node's CAN
#: receive thread takes too
FLOOR_PRIORITY = 5
FLOOR_TOPIC = "/bench_floor/joint_states"


def floor_sender(port: int, rate: float) -> int:
    """Send a datagram holding ``time.time_ns()`` to 127.0.0.1:``port`` ``rate`` times a
    second (started with :func:`_die_with_parent`: it ends with the floor publisher)."""
    import socket
    import struct

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    period, due = 1.0 / rate, time.monotonic()
    while True:
        due += period
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        sock.sendto(struct.pack("<q", time.time_ns()), ("127.0.0.1", port))


def _kernel_receive(sock: Any) -> tuple[bytes, int]:
    """One datagram of ``sock`` (SO_TIMESTAMPNS on) and its kernel receive time (ns, 0: none),
    as the node's udp_multicast bus receives each frame."""
    import socket
    import struct

    data, ancillary, _, _ = sock.recvmsg(64, socket.CMSG_SPACE(16))
    for level, kind, raw in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(raw) >= 16:
            sec, nsec = struct.unpack("@ll", raw[:16])
            return data, sec * 1_000_000_000 + nsec
    return data, 0


#: Linux's SO_TIMESTAMPNS (Python's socket module may not name it)
SO_TIMESTAMPNS = 35


def floor_publisher(n_joints: int, rate: float, topic: str, span_log: str = "") -> int:
    """The least any rclpy node that publishes what it receives adds to the bare publisher.

    Another process sends a datagram stamped with its send time ``rate`` times a second (as a
    station's last TPDO reaches the node); a thread of this node, blocked on the socket at
    ``FLOOR_PRIORITY`` as the node's CAN receive thread is, wakes and publishes an N-joint
    JointState stamped with that send time at once: no simulation, no CAN decoding, no
    hand-off to another thread, nothing computed. Runs until SIGINT.

    ``span_log``: a file that gets the floor's span per message as the node's span probe
    writes it (``ssi_bridge/ros/span_probe.py``): the datagram's kernel receive time
    (``SO_TIMESTAMPNS``, read with ``recvmsg`` as the node's bus reads its frames) and the
    instant ``publish()`` returned.
    """
    import socket
    import struct
    import threading

    from ssi_bridge.base.realtime import run_this_thread_at
    from ssi_bridge.tools.spin import spin_until_shutdown

    node, pub = _joint_state_publisher("floor", topic)
    names = [f"j{i + 1}" for i in range(n_joints)]
    from ssi_bridge.ros.span_probe import SpanProbe

    probe = SpanProbe(span_log) if span_log else None
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    sock.bind(("127.0.0.1", 0))
    # _die_with_parent: in this process _BENCH_PID is the floor publisher's own PID
    sender = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--floor-sender",
                               str(sock.getsockname()[1]), str(rate)],
                              preexec_fn=_die_with_parent)

    def receive() -> None:
        run_this_thread_at("floor_rx", FLOOR_PRIORITY)
        count = 0
        while True:
            data, received_ns = _kernel_receive(sock)
            sent_ns = struct.unpack("<q", data)[0]
            count += 1
            pub.publish(_joint_state(names, count, *divmod(sent_ns, 1_000_000_000)))
            if probe is not None:
                probe.published(received_ns / 1e9, n_joints)

    threading.Thread(target=receive, name="floor_rx", daemon=True).start()
    try:
        spin_until_shutdown(node)
    finally:
        sender.kill()
        sender.wait(5)
    return 0


# -- measurement --------------------------------------------------------------------------------
#: the CPU the pinned case keeps the whole node on (the last one of this machine)
PIN_CPU = max(os.sched_getaffinity(0))


def _domain_id() -> int:
    return random.Random(os.getpid() * 104729 + time.time_ns()).randint(1, 100)


_prctl = ctypes.CDLL(None, use_errno=True).prctl  # resolved before any fork
PR_SET_PDEATHSIG = 1
_BENCH_PID = os.getpid()


#: SCHED_FIFO priority of the subscriber process (0: normal scheduling)
SUBSCRIBER_PRIORITY = 3


@functools.cache
def subscriber_scheduling() -> str:
    """How the subscriber is scheduled, for the notes."""
    from ssi_bridge.base.realtime import fifo_permitted

    if fifo_permitted(SUBSCRIBER_PRIORITY):
        return f"subscriber SCHED_FIFO {SUBSCRIBER_PRIORITY}"
    return "subscriber normally scheduled (SCHED_FIFO not permitted)"


def _real_time_subscriber() -> None:
    """preexec_fn of the subscriber: as _die_with_parent, then SCHED_FIFO (every thread
    rclpy starts inherits it), or normal scheduling where that is not permitted."""
    _die_with_parent()
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(SUBSCRIBER_PRIORITY))
    except OSError:
        pass


def _die_with_parent() -> None:
    """preexec_fn of every process started here: SIGKILLed when this benchmark dies (a killed
    run leaves no publisher behind); SIGINT back to default (a background job of a
    non-interactive shell starts with it ignored) so that _stop's SIGINT is handled."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    _prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if os.getppid() != _BENCH_PID:
        os._exit(1)  # the benchmark died before prctl took effect


def _stop(proc: subprocess.Popen, timeout: float = 8.0) -> None:
    """SIGINT, then SIGKILL after ``timeout``; only this PID."""
    if proc.poll() is not None:
        return
    try:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(5)
    except ProcessLookupError:
        pass


def _tail(path: Path, n: int = 1500) -> str:
    try:
        return path.read_text(errors="replace")[-n:]
    except OSError:
        return ""


def case_rate(n_joints: int) -> float:
    """1 kHz, or the highest rate the wire allows for ``n_joints`` slots at BITRATE."""
    from ssi_bridge.protocol import wire
    return min(RATE_HZ, wire.max_cycle_rate(n_joints, BITRATE))


def after_sync_wire_s(n_joints: int) -> float:
    """Computed SYNC -> last TPDO wire time (s): the TPDOs of one cycle, worst-case stuffed."""
    from ssi_bridge.protocol import wire
    return sum(wire.worst_frame_bits(b) for b in wire.cycle_payloads(n_joints)[1:]) / BITRATE


def beyond_wire_us(n_joints: int, node: dict) -> tuple[float, Any]:
    """The computed SYNC -> last TPDO wire time (us) and the node's latencies minus it."""
    wire_us = after_sync_wire_s(n_joints) * 1e6
    return wire_us, node["latency"] - wire_us


def burners(n: int) -> list[subprocess.Popen]:
    """``n`` CPU-burning processes (stopped by PID with :func:`_stop`)."""
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"],
                             start_new_session=True) for _ in range(n)]


def descendants(pid: int) -> list[int]:
    """The PIDs of ``pid``'s child processes and theirs (the node's station child)."""
    found: list[int] = []
    todo = [pid]
    while todo:
        parent = todo.pop()
        for task in Path(f"/proc/{parent}/task").glob("*/children"):
            try:
                kids = [int(k) for k in task.read_text().split()]
            except OSError:
                continue
            found += kids
            todo += kids
    return found


def _cpu_of(pids: list[int]) -> float:
    total = 0.0
    for pid in pids:
        try:
            total += cpu_seconds(pid)
        except OSError:
            pass
    return total


def span_window(path: Path, w0: int, w1: int) -> Any:
    """Spans (us) of the records of a span file published within [w0, w1) (wall ns)."""
    import numpy as np

    from ssi_bridge.ros.span_probe import read_spans

    rows = np.array(read_spans(str(path)), dtype=np.int64).reshape(-1, 3)
    sel = (rows[:, 1] >= w0) & (rows[:, 1] < w1) & (rows[:, 0] > 0)
    return (rows[sel, 1] - rows[sel, 0]) / 1e3


def measure(tag: str, cmd: list[str], topic: str, env: dict[str, str], work: Path,
            rate: float = RATE_HZ, spans: Path | None = None, span_env: bool = True) -> dict:
    """Run ``cmd`` (the publisher) and the subscriber; return the window's figures.

    ``spans``: the span file the publisher writes (``span_env``: named by
    ``SSI_BRIDGE_SPAN_LOG`` in its environment, set here, as the node reads it; else the
    command line names it, as the floor's); its records in the window become
    ``span`` (us) in the result. ``cpu_s_per_s`` is the publisher process alone (its threads;
    a child process such as the node's station is not in its utime+stime), and
    ``children_cpu_s_per_s`` its child processes'.
    """
    import numpy as np

    if spans is not None and span_env:
        env = {**env, SPAN_ENV: str(spans)}

    out = work / f"{tag}.samples"
    ready = work / f"{tag}.ready"
    pub_log = work / f"{tag}.pub.log"
    sub_log = work / f"{tag}.sub.log"
    procs: list[subprocess.Popen] = []
    try:
        with open(sub_log, "wb") as log:
            sub = subprocess.Popen([sys.executable, str(SUBSCRIBER), topic, str(out), str(ready)],
                                   stdout=log, stderr=subprocess.STDOUT, env=env, cwd=work,
                                   start_new_session=True,
                                   preexec_fn=_real_time_subscriber)
        procs.append(sub)
        with open(pub_log, "wb") as log:
            pub = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, cwd=work,
                                   start_new_session=True,
                                   preexec_fn=_die_with_parent)
        procs.append(pub)
        deadline = time.monotonic() + STARTUP_TIMEOUT_S
        while not ready.exists():
            for p, log in ((pub, pub_log), (sub, sub_log)):
                if p.poll() is not None:
                    raise RuntimeError(f"{tag}: {p.args[0]} exited {p.returncode}: {_tail(log)}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"{tag}: no message on {topic} within {STARTUP_TIMEOUT_S} s; "
                                   f"publisher log: {_tail(pub_log)}")
            time.sleep(0.05)
        time.sleep(WARMUP_S)
        kids = descendants(pub.pid)
        cpu0, kid0, w0, m0 = (cpu_seconds(pub.pid), _cpu_of(kids), time.time_ns(),
                              time.monotonic())
        time.sleep(MEASURE_S)
        cpu1, kid1, w1, m1 = (cpu_seconds(pub.pid), _cpu_of(kids), time.time_ns(),
                              time.monotonic())
        if pub.poll() is not None:
            raise RuntimeError(f"{tag}: publisher exited {pub.returncode}: {_tail(pub_log)}")
        _stop(sub)
        if not out.exists():
            raise RuntimeError(f"{tag}: subscriber wrote no samples: {_tail(sub_log)}")
    finally:
        for p in reversed(procs):
            _stop(p)

    data = np.loadtxt(out, dtype=np.int64, ndmin=2)
    recv, stamp = data[:, 0], data[:, 1]
    sel = (recv >= w0) & (recv < w1)
    recv, stamp = recv[sel], stamp[sel]
    window = (w1 - w0) / 1e9
    if len(recv) < 3:
        raise RuntimeError(f"{tag}: only {len(recv)} messages in the {window:.1f} s window")
    period_us = 1e6 / rate
    jitter = np.abs(np.diff(recv) / 1e3 - period_us)
    latency = (recv - stamp) / 1e3
    log = _tail(pub_log, 200_000)
    return {
        "latency": latency,
        "received": len(recv),
        "expected": rate * window,
        "stamp_inversions": int(np.sum(np.diff(stamp) <= 0)),
        "spurious_faults": log.count("EMCY") + log.count("silent"),
        "rate_hz": len(recv) / window,
        "jitter_p99_us": float(np.percentile(jitter, 99)),
        "latency_p50_us": float(np.percentile(latency, 50)),
        "latency_p99_us": float(np.percentile(latency, 99)),
        "cpu_s_per_s": (cpu1 - cpu0) / (m1 - m0),
        "children_cpu_s_per_s": (kid1 - kid0) / (m1 - m0),
        "span": (span_window(spans, w0, w1) if spans is not None and spans.exists()
                 else np.array([])),
    }


def driver_run(n_joints: int, run: int, domain_id: int, env: dict[str, str],
               work: Path) -> tuple[dict, dict, dict, dict]:
    """One run of a case: the node with its simulated station, the node as a real deployment
    runs it (``real_station.py``), the bare and the floor publisher, one after the other, the
    nodes and the floor writing their spans."""
    from real_station import real_params, station_process

    rate = case_rate(n_joints)
    node = measure(f"node{n_joints}r{run}", node_cmd(n_joints, domain_id, work),
                   f"{NODE_NS}/joint_states", env, work, rate,
                   spans=work / f"node{n_joints}r{run}.spans")
    extra = real_params(f"{domain_id}_{n_joints}_{run}")
    cmd = node_cmd(n_joints, domain_id, work, extra)
    with station_process(REPO, Path(cmd[cmd.index("--params-file") + 1]),
                         extra["bus.channel"], env, work / f"station{n_joints}r{run}.log"):
        real = measure(f"real{n_joints}r{run}", cmd, f"{NODE_NS}/joint_states", env, work,
                       rate, spans=work / f"real{n_joints}r{run}.spans")
    bare = measure(f"bare{n_joints}r{run}", bare_cmd(n_joints), BARE_TOPIC, env, work, rate)
    spans = work / f"floor{n_joints}r{run}.spans"
    floor = measure(f"floor{n_joints}r{run}", floor_cmd(n_joints, spans), FLOOR_TOPIC, env,
                    work, rate, spans=spans, span_env=False)
    return node, bare, floor, real


def node_cmd(n_joints: int, domain_id: int, work: Path,
             extra: dict | None = None) -> list[str]:
    """The installed node with ``n_joints`` simulated encoders at their case rate."""
    import yaml

    names = [f"j{i + 1}" for i in range(n_joints)]
    params: dict = {"publish_rate": case_rate(n_joints), "bus.bitrate": BITRATE,
                    "joints": names,
                    "bus.channel": f"bench_node_{domain_id}_{n_joints}",
                    "storage_path": str(work / f"bank{n_joints}" / "retentive.json")}
    for i, name in enumerate(names):
        params[f"{name}.slot"] = i + 1
    params.update(extra or {})
    pfile = work / f"params{n_joints}{'_x' if extra else ''}.yaml"
    pfile.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
    return [str(NODE_EXE), "--ros-args", "--params-file", str(pfile),
            "-r", f"__ns:={NODE_NS}"]


def bare_cmd(n_joints: int) -> list[str]:
    return [sys.executable, str(Path(__file__).resolve()), "--bare", str(n_joints),
            str(case_rate(n_joints)), BARE_TOPIC]


def floor_cmd(n_joints: int, spans: Path | None = None) -> list[str]:
    return [sys.executable, str(Path(__file__).resolve()), "--floor", str(n_joints),
            str(case_rate(n_joints)), FLOOR_TOPIC] + ([str(spans)] if spans else [])


def report(records: list[dict], n_joints: int, node: dict, bare: dict, label: str = "") -> None:
    for key, note in NOTES.items():
        value, base = node[key], bare[key]
        rec: dict = {"metric": f"node_{n_joints}enc{label}_{key}", "value": round(value, 3),
                     "unit": UNITS[key], "baseline": round(base, 3)}
        if base:
            rec["ratio"] = round(value / base, 3)
        if key in GOALS and "ratio" in rec:
            op, goal = GOALS[key]
            rec["goal"] = f"ratio {op} {goal}"
            rec["goal_met"] = bool(rec["ratio"] >= goal if op == ">=" else rec["ratio"] <= goal)
        pinned = ", node pinned to one CPU (cpu_affinity)" if label else ""
        rec["note"] = (f"{note}; {n_joints} encoder(s) at {case_rate(n_joints):g} Hz, "
                       f"{BITRATE} bit/s{pinned}, baseline = bare "
                       f"rclpy timer publisher of a {n_joints}-joint JointState, same subscriber "
                       f"({subscriber_scheduling()})")
        emit(records, rec)
    if label:
        return
    import numpy as np
    wire_us, beyond = beyond_wire_us(n_joints, node)
    for q in (50, 99):
        value, base = float(np.percentile(beyond, q)), float(np.percentile(bare["latency"], q))
        rec = {"metric": f"node_{n_joints}enc_latency_beyond_wire_p{q}_us", "value": round(value, 1),
               "unit": "us", "baseline": round(base, 1), "ratio": round(value / base, 3),
               "note": f"receive - header.stamp - computed SYNC->last TPDO wire time "
                       f"({wire_us:.0f} us, {n_joints} slot(s) at {BITRATE} bit/s, "
                       f"{case_rate(n_joints):g} Hz); baseline = bare publisher's latency; "
                       f"{subscriber_scheduling()}"}
        if q == 99:
            rec["goal"] = "ratio <= 1.2"
            rec["goal_met"] = rec["ratio"] <= 1.2
        emit(records, rec)


def report_floor(records: list[dict], n_joints: int, node: dict, bare: dict,
                 floor: dict) -> None:
    """The floor publisher against the bare one, and the node's latency beyond the wire
    against the floor: what the bridge adds beyond what any receiving rclpy node adds."""
    import numpy as np
    wire_us, beyond = beyond_wire_us(n_joints, node)
    where = (f"{n_joints} joint(s) at {case_rate(n_joints):g} Hz; {subscriber_scheduling()}; "
             f"floor received {floor['rate_hz']:.0f} msg/s")
    for q in (50, 99):
        f, b, nb = (float(np.percentile(x, q)) for x in (floor["latency"], bare["latency"],
                                                        beyond))
        emit(records, {
            "metric": f"node_{n_joints}enc_latency_floor_p{q}_us", "value": round(f, 1),
            "unit": "us", "baseline": round(b, 1), "ratio": round(f / b, 3),
            "note": "receive - send time of a datagram another process sent, published at "
                    "once by the rclpy thread it woke (SCHED_FIFO "
                    f"{FLOOR_PRIORITY}): the least a node publishing what it receives adds; "
                    f"baseline = bare publisher's latency; {where}"})
        emit(records, {
            "metric": f"node_{n_joints}enc_latency_beyond_wire_vs_floor_p{q}_us",
            "value": round(nb, 1), "unit": "us", "baseline": round(f, 1),
            "ratio": round(nb / f, 3),
            "note": f"the node's latency beyond the wire ({wire_us:.0f} us subtracted) against "
                    f"the floor publisher's latency; {where}"})


#: the two ways the driver-only figures run the node: metric label, what the node process holds
DRIVER_SETUPS = {
    "sim": ("", "node with simulation.enabled (its station a child process on udp_multicast; "
                "the node's own bus end is the simulated wire, its SYNC paced at bit time in "
                "the node process)"),
    "real": ("_real", "node as a real deployment runs it: simulation.enabled:=false on "
                      "udp_multicast, the `station` program a separate process (the node "
                      "process holds the driver alone)"),
}


def report_driver(records: list[dict], n_joints: int, runs: list[tuple[dict, dict, dict]],
                  setup: str = "sim") -> None:
    """The driver alone, medians of the runs' ratios (each run against its own baselines).

    Latency: the node's span from the kernel receive time of the frame that completed a
    cycle to ``publish()`` returning (``ros/span_probe.py``) against the floor publisher's
    same span (datagram in the kernel to ``publish()`` returning). CPU: the node's process
    alone (not its station child) against the bare publisher's.
    """
    import statistics

    import numpy as np

    label, how = DRIVER_SETUPS[setup]
    where = (f"{how}; {n_joints} joint(s) at {case_rate(n_joints):g} Hz, {BITRATE} bit/s; median of "
             f"{len(runs)} runs in one sitting, each against its own baselines")
    usable = [(n, b, f) for n, b, f in runs if len(n["span"]) and len(f["span"])]
    for q in (50, 99):
        if not usable:
            emit(records, {"metric": f"node_{n_joints}enc_driver{label}_latency_p{q}_us",
                           "error": "no span records (the node or floor wrote none)"})
            continue
        d = [float(np.percentile(n["span"], q)) for n, _, _ in usable]
        f = [float(np.percentile(fl["span"], q)) for _, _, fl in usable]
        ratios = [a / b for a, b in zip(d, f)]
        rec: dict = {
            "metric": f"node_{n_joints}enc_driver{label}_latency_p{q}_us",
            "value": round(statistics.median(d), 1), "unit": "us",
            "baseline": round(statistics.median(f), 1),
            "ratio": round(statistics.median(ratios), 3),
            "runs": [round(r, 3) for r in ratios],
            "note": "the driver's span: kernel receive time of the frame that completed a "
                    "cycle -> publish() returned (ros/span_probe.py); baseline = the floor "
                    "publisher's span, datagram in the kernel -> publish() returned; ratio = "
                    f"median of the runs' ratios; {where}"}
        if q == 99:
            rec["goal"] = f"ratio <= {DRIVER_GOALS['latency_p99']}"
            rec["goal_met"] = rec["ratio"] <= DRIVER_GOALS["latency_p99"]
        emit(records, rec)
    cpu = [n["cpu_s_per_s"] for n, _, _ in runs]
    bare = [b["cpu_s_per_s"] for _, b, _ in runs]
    ratios = [a / b for a, b in zip(cpu, bare) if b]
    rec = {"metric": f"node_{n_joints}enc_driver{label}_cpu_s_per_s",
           "value": round(statistics.median(cpu), 3), "unit": "s/s",
           "baseline": round(statistics.median(bare), 3),
           "ratio": round(statistics.median(ratios), 3) if ratios else None,
           "runs": [round(r, 3) for r in ratios],
           "goal": f"ratio <= {DRIVER_GOALS['cpu']}",
           "note": "utime+stime of the node's process alone (no station process counted: a "
                   "real deployment has none) per s; baseline = bare rclpy timer publisher; "
                   f"ratio = median of the runs' ratios; {where}"}
    rec["goal_met"] = rec["ratio"] is not None and rec["ratio"] <= DRIVER_GOALS["cpu"]
    emit(records, rec)
    if setup != "sim":
        return
    emit(records, {"metric": f"node_{n_joints}enc_station_child_cpu_s_per_s",
                   "value": round(statistics.median(n["children_cpu_s_per_s"]
                                                    for n, _, _ in runs), 3),
                   "unit": "s/s",
                   "note": f"the simulated station's child process (not the driver's); {where}"})


def report_loaded(records: list[dict], n_joints: int, node: dict) -> None:
    """The loaded-machine run: what two CPU burners cost the node (no baseline: counts)."""
    rate = case_rate(n_joints)
    missed = max(0.0, 1.0 - node["received"] / node["expected"])
    for metric, value, unit, note in (
            ("cycles_missed_fraction", round(missed, 4), "fraction",
             "1 - received / (rate x window): SYNC cycles skipped or not published"),
            ("spurious_faults", node["spurious_faults"], "count",
             "EMCY or 'silent' lines in the node's log, no fault injected"),
            ("stamp_inversions", node["stamp_inversions"], "count",
             "non-increasing header.stamp among received messages")):
        emit(records, {"metric": f"node_{n_joints}enc_loaded_{metric}", "value": value,
                       "unit": unit, "note": f"{note}; {n_joints} encoder(s) at {rate:g} Hz, "
                       f"{BITRATE} bit/s, beside two CPU-burning processes (one per core); "
                       f"{subscriber_scheduling()}"})


def stations_cmd(n_stations: int, slots: int, domain_id: int, work: Path,
                 transport: str = "virtual") -> list[str]:
    """The node as master of ``n_stations`` simulated stations of ``slots`` encoders each."""
    import yaml

    ids = [1 + 2 * k for k in range(n_stations)]  # node ids 1, 3, 5, 7
    names = [f"s{sid}j{slot}" for sid in ids for slot in range(1, slots + 1)]
    params: dict = {"publish_rate": STATIONS_RATE_HZ, "joints": names, "stations": ids,
                    "simulation.transport": transport,
                    "bus.bitrate": STATIONS_BITRATE,
                    "bus.channel": f"bench_st_{domain_id}_{n_stations}x{slots}_{transport}",
                    "storage_path": str(work / f"st{n_stations}x{slots}" / "retentive.json")}
    for sid in ids:
        for slot in range(1, slots + 1):
            params[f"s{sid}j{slot}.station"] = sid
            params[f"s{sid}j{slot}.slot"] = slot
    pfile = work / f"stations{n_stations}x{slots}_{transport}.yaml"
    pfile.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
    return [str(NODE_EXE), "--ros-args", "--params-file", str(pfile),
            "-r", f"__ns:={NODE_NS}"]


def run_stations(records: list[dict], domain_id: int, env: dict[str, str], work: Path) -> None:
    """4 stations x 2 slots against 1 station x 8 slots, same rate, same run.

    Both carry 12 TPDOs + 1 SYNC per cycle (8 images, 4 position pairs), so the wire time is
    the same; the cost should follow the slots, not the stations (ratio ~1). ``virtual``: the
    simulated stations run in the node's process (each its own bus receiver of every frame,
    as each real device has its own CAN controller), so the node's CPU includes them;
    ``udp_multicast``: one child process per station, the node's CPU is the master's alone.
    """
    for transport, label in (("virtual", ""), ("udp_multicast", "_master_only")):
        one = measure(f"st1x8{transport}", stations_cmd(1, 8, domain_id, work, transport),
                      f"{NODE_NS}/joint_states", env, work, STATIONS_RATE_HZ)
        four = measure(f"st4x2{transport}", stations_cmd(4, 2, domain_id, work, transport),
                       f"{NODE_NS}/joint_states", env, work, STATIONS_RATE_HZ)
        for key in ("cpu_s_per_s", "latency_p50_us", "latency_p99_us", "rate_hz"):
            base = one[key]
            rec: dict = {"metric": f"node_4stations_2slots{label}_{key}",
                         "value": round(four[key], 3), "unit": UNITS[key],
                         "baseline": round(base, 3)}
            if base:
                rec["ratio"] = round(four[key] / base, 3)
            where = ("stations in the node's process (virtual)" if transport == "virtual" else
                     "one station child process each (udp_multicast), node CPU = master only")
            rec["note"] = (f"{NOTES[key]}; one master driving 4 simulated stations x 2 slots at "
                           f"{STATIONS_RATE_HZ:g} Hz, {STATIONS_BITRATE // 1000} kbit/s, {where}; "
                           "baseline = 1 station x 8 slots, same rate, same run (same 13 frames "
                           "per cycle)")
            emit(records, rec)
# -- live view (foxglove.port): node CPU with one Foxglove WebSocket client vs none -------------
LIVEVIEW_ROUNDS = 3
LIVEVIEW_WINDOW_S = 3.0
#: what the client subscribes to: joint_states alone (a plot panel), or every node topic
LIVEVIEW_CASES = {"client": [f"{NODE_NS}/joint_states"],
                  "all_topics": [f"{NODE_NS}/joint_states", f"{NODE_NS}/ssi_bridge/status",
                                 "/diagnostics", f"{NODE_NS}/ssi_bridge/events"]}


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_file(path: Path, procs: list[tuple[subprocess.Popen, Path]], what: str) -> None:
    deadline = time.monotonic() + STARTUP_TIMEOUT_S
    while not path.exists():
        for p, log in procs:
            if p.poll() is not None:
                raise RuntimeError(f"{what}: {p.args[1] if len(p.args) > 1 else p.args[0]} "
                                   f"exited {p.returncode}: {_tail(log)}")
        if time.monotonic() > deadline:
            raise RuntimeError(f"{what}: nothing within {STARTUP_TIMEOUT_S} s")
        time.sleep(0.05)


def _cpu_window(pid: int) -> tuple[float, float, int, int]:
    """(CPU s, elapsed s, wall ns start, wall ns end) of ``pid`` over LIVEVIEW_WINDOW_S."""
    cpu0, m0, w0 = cpu_seconds(pid), time.monotonic(), time.time_ns()
    time.sleep(LIVEVIEW_WINDOW_S)
    return cpu_seconds(pid) - cpu0, time.monotonic() - m0, w0, time.time_ns()


def measure_liveview(domain_id: int, env: dict[str, str], work: Path) -> dict[str, list[float]]:
    """One node (1 encoder, 1 kHz, live view on), alternating windows with no client, one
    client on joint_states and one on every topic: node CPU s/s, and the joint_states rates
    the WebSocket client and the DDS subscriber received."""
    port = _free_port()
    cmd = node_cmd(1, domain_id, work, {"foxglove.port": port})
    windows: dict[str, list[tuple[float, float, int, int]]] = {"idle": [], **{
        case: [] for case in LIVEVIEW_CASES}}
    ws_rates: list[float] = []
    procs: list[subprocess.Popen] = []
    ready, pub_log, sub_log = work / "lv.ready", work / "lv.pub.log", work / "lv.sub.log"
    try:
        with open(sub_log, "wb") as log:
            procs.append(subprocess.Popen(
                [sys.executable, str(SUBSCRIBER), f"{NODE_NS}/joint_states",
                 str(work / "lv.samples"), str(ready)], stdout=log, stderr=subprocess.STDOUT,
                env=env, cwd=work, start_new_session=True))
        with open(pub_log, "wb") as log:
            node = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env,
                                    cwd=work, start_new_session=True)
        procs.append(node)
        _wait_file(ready, [(node, pub_log)], "live view node: first joint_states")
        time.sleep(WARMUP_S)
        for r in range(LIVEVIEW_ROUNDS):
            windows["idle"].append(_cpu_window(node.pid))
            for case, topics in LIVEVIEW_CASES.items():
                tag = f"lv_{case}_{r}"
                c_ready, c_out, c_log = (work / f"{tag}.ready", work / f"{tag}.out",
                                         work / f"{tag}.log")
                with open(c_log, "wb") as log:
                    client = subprocess.Popen(
                        [sys.executable, str(LIVEVIEW_CLIENT), f"ws://127.0.0.1:{port}",
                         ",".join(topics), str(c_ready), str(c_out)], stdout=log,
                        stderr=subprocess.STDOUT, env=env, cwd=work, start_new_session=True)
                try:
                    _wait_file(c_ready, [(client, c_log), (node, pub_log)],
                               f"live view client on {topics}")
                    time.sleep(0.5)
                    windows[case].append(_cpu_window(node.pid))
                finally:
                    _stop(client)
                if case == "client":
                    n, first, last = (int(v) for v in c_out.read_text().split())
                    ws_rates.append((n - 1) / ((last - first) / 1e9))
                time.sleep(0.5)  # the server notices the disconnect; serializing stops
    finally:
        for p in reversed(procs):
            _stop(p)
    import numpy as np

    recv = np.loadtxt(work / "lv.samples", dtype=np.int64, ndmin=2)[:, 0]
    out: dict[str, list[float]] = {"ws_rate_hz": ws_rates}
    for case, wins in windows.items():
        cycles = [int(((recv >= w0) & (recv < w1)).sum()) for _, _, w0, w1 in wins]
        out[case] = [cpu / el for cpu, el, _, _ in wins]
        out[f"{case}_dds_rate_hz"] = [n / (el or 1.0) for (_, el, _, _), n in zip(wins, cycles)]
    return out


def report_liveview(records: list[dict], lv: dict[str, list[float]], plain: dict) -> None:
    """Medians of the alternating windows; baselines from the same node or the same run."""
    import statistics

    med = {k: statistics.median(v) for k, v in lv.items()}
    rows = [
        ("client_cpu_s_per_s", med["client"], med["idle"], "s/s",
         "node CPU with one Foxglove WebSocket client subscribed to joint_states; baseline = "
         "the same node process, live view server on, no client (alternating windows)"),
        ("all_topics_cpu_s_per_s", med["all_topics"], med["idle"], "s/s",
         "node CPU with one client subscribed to joint_states, ~/status, /diagnostics and "
         "~/events (~/status is then built every cycle); baseline = same node, no client"),
        ("idle_cpu_s_per_s", med["idle"], plain["cpu_s_per_s"], "s/s",
         "node CPU with the live view server on and no client; baseline = node with "
         "foxglove.port 0 (the default) measured earlier in this run"),
        ("ws_rate_hz", med["ws_rate_hz"], med["client_dds_rate_hz"], "Hz",
         "joint_states per second received by the WebSocket client; baseline = joint_states "
         "per second received over DDS by the subscriber (also a Python process) in the same "
         "windows"),
    ]
    for name, value, base, unit, note in rows:
        rec = {"metric": f"node_1enc_liveview_{name}", "value": round(value, 3), "unit": unit,
               "baseline": round(base, 3)}
        if base:
            rec["ratio"] = round(value / base, 3)
        rec["note"] = (f"{note}; 1 encoder at {RATE_HZ:g} Hz, median of {LIVEVIEW_ROUNDS} "
                       f"windows of {LIVEVIEW_WINDOW_S:g} s")
        emit(records, rec)


def run(records: list[dict]) -> None:
    if os.environ.get("BENCH_NODE_ONLY") == "stations":
        domain_id = _domain_id()
        with tempfile.TemporaryDirectory(prefix="bench_node_") as tmp:
            run_stations(records, domain_id, dds_env(domain_id), Path(tmp))
        return
    if not NODE_EXE.exists():
        raise RuntimeError(f"{NODE_EXE} missing: run `make setup`")
    only = os.environ.get("BENCH_NODE_ONLY", "")
    domain_id = _domain_id()
    env = dds_env(domain_id)
    plain: dict[int, dict] = {}
    with tempfile.TemporaryDirectory(prefix="bench_node_") as tmp:
        work = Path(tmp)
        for n in CASES:
            try:
                runs = [driver_run(n, r, domain_id, env, work) for r in range(DRIVER_RUNS)]
                report_driver(records, n, [(nd, b, f) for nd, b, f, _ in runs])
                report_driver(records, n, [(r, b, f) for _, b, f, r in runs], "real")
                node, bare, floor, _ = runs[0]
                report(records, n, node, bare)
                report_floor(records, n, node, bare, floor)
                plain[n] = node
                if only == "driver":
                    continue
                if n == max(CASES):
                    pinned = measure(f"node{n}pin", node_cmd(n, domain_id, work, {
                        "cpu_affinity": [PIN_CPU]}), f"{NODE_NS}/joint_states", env, work,
                        case_rate(n))
                    report(records, n, pinned, bare, "_pinned")
            except Exception as err:  # noqa: BLE001 - a benchmark reports, never fails
                emit(records, {"metric": f"node_{n}enc", "error": f"{type(err).__name__}: {err}",
                               "note": traceback.format_exc(limit=3)[-800:]})
        if only == "driver":
            return
        try:
            run_stations(records, domain_id, env, work)
        except Exception as err:  # noqa: BLE001 - a benchmark reports, never fails
            emit(records, {"metric": "node_stations", "error": f"{type(err).__name__}: {err}",
                           "note": traceback.format_exc(limit=3)[-800:]})
        load = burners(2)
        try:
            node = measure("node1loaded", node_cmd(1, domain_id, work), f"{NODE_NS}/joint_states",
                           env, work, case_rate(1))
            report_loaded(records, 1, node)
        except Exception as err:  # noqa: BLE001
            emit(records, {"metric": "node_1enc_loaded", "error": f"{type(err).__name__}: {err}"})
        finally:
            for p in load:
                p.kill()
                p.wait(5)
        if 1 in plain:
            try:
                report_liveview(records, measure_liveview(domain_id, env, work), plain[1])
            except Exception as err:  # noqa: BLE001
                emit(records, {"metric": "node_1enc_liveview",
                               "error": f"{type(err).__name__}: {err}",
                               "note": traceback.format_exc(limit=3)[-800:]})


def main() -> int:
    records: list[dict] = []
    try:
        run(records)
    except Exception as err:  # noqa: BLE001
        emit(records, {"metric": "node", "error": f"{type(err).__name__}: {err}"})
    if os.environ.get("BENCH_NODE_ONLY"):
        save(records)
        return 0
    try:  # the service-burst part; `python bench/service_burst.py` runs it alone
        sys.path.insert(0, str(HERE))
        import service_burst

        service_burst.run(records)
    except Exception as err:  # noqa: BLE001
        emit(records, {"metric": "service_burst", "error": f"{type(err).__name__}: {err}"})
    save(records)
    return 0


if __name__ == "__main__":
    if len(sys.argv) == 5 and sys.argv[1] == "--bare":
        sys.exit(bare_publisher(int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]))
    if len(sys.argv) in (5, 6) and sys.argv[1] == "--floor":
        sys.exit(floor_publisher(int(sys.argv[2]), float(sys.argv[3]), sys.argv[4],
                                 *sys.argv[5:]))
    if len(sys.argv) == 4 and sys.argv[1] == "--floor-sender":
        sys.exit(floor_sender(int(sys.argv[2]), float(sys.argv[3])))
    sys.exit(main())
