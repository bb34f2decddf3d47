"""Total latency beyond the wire of two code versions' nodes, driven by one station process.

Usage: ``python bench/node_samestation.py OLD_CHECKOUT [--runs N] [--cases 1,8] [--station
new|old]`` (from this
checkout, ``source scripts/env.sh`` first; OLD_CHECKOUT is another checkout of the repository,
set up with its own ``make setup``: its .venv and install/). Also
``BENCH_NODE_ONLY=samestation BENCH_NODE_OLD=OLD_CHECKOUT make bench ONLY=node``.

The node benchmark's headline "latency beyond the wire" subtracts the computed wire time of a
cycle's TPDOs from the node's latency; the rest holds the station's own reaction too. When the
simulated station changes (its TPDOs now leave after the SSI reads they carry, as a real module
must), two code versions each measured with its own station compare two simulators, not two
drivers. Here, for each case (1 encoder at 1 kHz, 8 at 480 Hz), ONE ``station`` process of this
checkout (``real_station.py``) runs throughout, and the node of this checkout ("new") and of
OLD_CHECKOUT ("old") drive it in turn, each as a real deployment (simulation off, udp_multicast,
its own checkout's install and environment), alternating new/old, old/new, ... for
:data:`RUNS` pairs. Each run measures as ``node_measure.measure`` (warm-up, then a window) with
the same subscriber, and a sniffer on the bus group (:class:`Sniffer`, in this process) logs the
kernel receive time and COB-ID of every frame, so each published sample splits into

* ``to_sync``: header.stamp -> the SYNC in the kernel (the node's send),
* ``station``: the SYNC in the kernel -> the cycle's last TPDO in the kernel (the station's
  reaction and the frames' wire time; loopback delivers one datagram to every member of the
  group at once, so this is the station's own receive and send time),
* ``after``: the last TPDO in the kernel -> the subscriber's receive (the driver and DDS).

``--station old`` has the other checkout's station program answer both nodes instead (its
simulator, e.g. from before the TPDOs waited for the SSI reads; records
``node_samestation_oldstation_*``), which shows how much of a change between the checkouts'
figures is the simulator's.

Records ``node_samestation_<N>enc_<figure>_p50_us`` / ``_p99_us``: value = new, baseline = old
(medians of the runs), ratio = median of the pairs' ratios. Figures: ``beyond_wire`` (receive -
stamp - computed wire time, the headline), ``station_share`` (``station`` minus the computed
wire time: the simulator's part of ``beyond_wire``; no ratio, it lies near 0 with 8 slots),
``station_beyond_frames`` (``station`` minus the cycle's frames' own wire time, their real
stuffing: the station's reaction), ``station_first_tpdo`` (SYNC -> first TPDO),
``after_station`` (``after``), ``to_sync``, ``span`` (the node's own, where it writes one);
and ``cpu_s_per_s`` of the node process.
Printed, appended to bench/results/latest.jsonl and written to
bench/results/node_samestation_<UTC time>.jsonl.
"""

from __future__ import annotations

import argparse
import datetime
import os
import socket
import statistics
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from benchlib import RESULTS, cpu_seconds, save
from benchlib import emit_record as emit
from node_cases import BITRATE, CASES, NODE_NS, REPO, after_sync_wire_s, case_rate
from node_measure import MEASURE_S, SPAN_ENV, WARMUP_S, publisher_and_subscriber, span_window
from node_procs import dds_env, domain_id
from real_station import real_params, station_process

#: A/B pairs per case (each pair one run of each node, the order alternating)
RUNS = 3
#: how often the sniffer empties its socket (s): frames keep their kernel time in the queue
DRAIN_S = 0.02
#: the station's SCHED_FIFO priority, given to either checkout's program (this one's default,
#: and the priority every checkout's node gives its station child: simulation.station_priority)
STATION_PRIORITY = "10"
SYNC_ID = 0x080
#: TPDO COB-IDs (PDO1-4 and the encoder PDOs 9-12 of a node id, 000 Table 15): below the SDOs
TPDO_IDS = (0x180, 0x580)
#: environment keys of the measurement that each node gets on top of its checkout's env.sh
DDS_KEYS = ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS", "RMW_",
            "PYTHONUNBUFFERED", "FASTRTPS_", "FASTDDS_", "CYCLONEDDS_")
#: the PATH of the clean environment every checkout's env.sh is sourced in
BASE_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
SO_TIMESTAMPNS = 35
SO_RCVBUFFORCE = 33


def checkout_env(root: Path) -> dict[str, str]:
    """The environment ``root/scripts/env.sh`` makes from a clean one (that checkout's .venv,
    install/ and ROS variables).

    :raises RuntimeError: env.sh failed (the checkout is not set up)
    """
    out = subprocess.run(["env", "-i", f"HOME={os.environ.get('HOME', '/')}",
                          f"PATH={BASE_PATH}", "bash", "-c",
                          f"source {root / 'scripts' / 'env.sh'} >/dev/null && env -0"],
                         capture_output=True, check=False, cwd=root)
    if out.returncode:
        raise RuntimeError(f"{root}: scripts/env.sh failed: {out.stderr.decode()[-500:]}")
    pairs = (item.split("=", 1) for item in out.stdout.decode().split("\0") if "=" in item)
    return {k: v for k, v in pairs if k not in ("PWD", "SHLVL", "_", "PS1")}


def node_command(root: Path, env: dict[str, str], n_joints: int, channel: str, work: Path,
                 tag: str) -> list[str]:
    """``root``'s installed node, run under ``env -i`` with ``env`` (its checkout's), as a
    real deployment on ``channel``: its parameters written to ``work/<tag>.yaml`` with that
    checkout's name of the simulation switch (``simulation.enabled``, earlier ``simulation``).

    :raises RuntimeError: ``root`` has no installed node
    """
    import yaml

    exe = root / "install" / "ssi_bridge" / "lib" / "ssi_bridge" / "ssi_bridge_node"
    if not exe.exists():
        raise RuntimeError(f"{exe} missing: run `make setup` in {root}")
    table = (root / "ssi_bridge" / "ros" / "param_table.py").read_text(encoding="utf-8")
    switch = "simulation.enabled" if '"simulation.enabled"' in table else "simulation"
    names = [f"j{i + 1}" for i in range(n_joints)]
    params: dict[str, Any] = {"publish_rate": case_rate(n_joints), "bus.bitrate": BITRATE,
                              "joints": names, switch: False,
                              "bus.interface": "udp_multicast", "bus.channel": channel}
    for i, name in enumerate(names):
        params[f"{name}.slot"] = i + 1
    pfile = work / f"{tag}.yaml"
    pfile.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
    return ["env", "-i", *(f"{k}={v}" for k, v in env.items()), str(exe), "--ros-args",
            "--params-file", str(pfile), "-r", f"__ns:={NODE_NS}"]


class Sniffer:
    """Every frame on a udp_multicast group: its kernel receive time (ns) and COB-ID.

    A socket of its own joined to the group (SO_REUSEADDR/SO_REUSEPORT like the bus's, so
    every member gets each datagram), emptied every :data:`DRAIN_S` by a thread that only
    stores the datagrams: decoding waits for :meth:`frames`, so the sniffer costs the machine
    little while the nodes run.
    """

    def __init__(self, channel: str) -> None:
        from ssi_bridge.base.udp_bus import parse_channel

        ep = parse_channel(channel)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        try:
            sock.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, 16 << 20)
        except OSError:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 16 << 20)
        sock.bind((ep.group, ep.port))
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP,
                        socket.inet_aton(ep.group) + socket.inet_aton(ep.interface))
        self._sock = sock
        self._raw: list[tuple[bytes, list[tuple[int, int, bytes]]]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._drain, name="sniffer", daemon=True)
        self._thread.start()

    def _drain(self) -> None:
        recv, space, keep = self._sock.recvmsg, socket.CMSG_SPACE(16), self._raw.append
        while True:
            stopping = self._stop.wait(DRAIN_S)
            while True:
                try:
                    data, ancillary, _, _ = recv(512, space, socket.MSG_DONTWAIT)
                except BlockingIOError:
                    break
                keep((data, ancillary))
            if stopping:
                return

    def close(self) -> None:
        """Read what is queued, then close the socket."""
        self._stop.set()
        self._thread.join(5)
        self._sock.close()

    def frames(self) -> Any:
        """(kernel ns, COB-ID, bits on the wire incl. stuffing) of every frame sniffed, an
        int64 array of shape (n, 3); datagrams that are no python-can frame are left out."""
        import numpy as np

        from ssi_bridge.base.udp_frames import unpack_frame
        from ssi_bridge.protocol.wire import frame_bits

        rows = []
        for data, ancillary in self._raw:
            stamp = next((struct.unpack("@ll", raw[:16]) for level, kind, raw in ancillary
                          if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS), None)
            try:  # the bus's own decoder (python-can's fields)
                msg = unpack_frame(data, 0.0)
                cob = msg.arbitration_id
                bits = frame_bits(cob, msg.data, msg.is_remote_frame, msg.dlc)
            except Exception:  # noqa: BLE001 - what python-can's unpack raises: no frame
                continue
            if stamp is not None:
                rows.append((stamp[0] * 1_000_000_000 + stamp[1], cob, bits))
        return np.array(rows, dtype=np.int64).reshape(-1, 3)


def one_run(tag: str, cmd: list[str], channel: str, env: dict[str, str], work: Path,
            rate: float) -> dict[str, Any]:
    """The node ``cmd`` published to the subscriber while the sniffer logs the bus: the
    window's samples (receive ns, stamp ns), frames, the node's CPU per s and, where the node
    writes them (a checkout with ``ros/span_probe.py``; :data:`SPAN_ENV` is set for every
    node), its spans (us: the completing frame in the kernel -> ``publish()`` returned).

    :raises RuntimeError: as ``node_measure.publisher_and_subscriber``, the node exited in
        the window, or the window held fewer than 3 messages
    """
    import numpy as np

    spans = work / f"{tag}.spans"
    cmd = [*cmd[:2], f"{SPAN_ENV}={spans}", *cmd[2:]]  # env -i KEY=VALUE ...
    sniffer = Sniffer(channel)
    try:
        with publisher_and_subscriber(tag, cmd, f"{NODE_NS}/joint_states", env, work) as run:
            time.sleep(WARMUP_S)
            cpu0, w0, m0 = cpu_seconds(run.pub.pid), time.time_ns(), time.monotonic()
            time.sleep(MEASURE_S)
            cpu1, w1, m1 = cpu_seconds(run.pub.pid), time.time_ns(), time.monotonic()
            if run.pub.poll() is not None:
                raise RuntimeError(f"{tag}: node exited {run.pub.returncode}")
    finally:
        sniffer.close()
    data = np.loadtxt(run.samples, dtype=np.int64, ndmin=2)
    data = data[(data[:, 0] >= w0) & (data[:, 0] < w1)]
    if len(data) < 3:
        raise RuntimeError(f"{tag}: only {len(data)} messages in the window")
    frames = sniffer.frames()
    frames = frames[(frames[:, 0] >= w0 - 10_000_000) & (frames[:, 0] < w1 + 10_000_000)]
    return {"recv": data[:, 0], "stamp": data[:, 1], "frames": frames, "rate": rate,
            "span": span_window(spans, w0, w1) if spans.exists() else np.array([]),
            "rate_hz": len(data) / ((w1 - w0) / 1e9), "cpu_s_per_s": (cpu1 - cpu0) / (m1 - m0)}


def split(run: dict[str, Any], n_joints: int) -> dict[str, Any]:
    """A run's figures (us arrays): ``beyond_wire`` per sample; per sample matched to its
    SYNC (the nearest within a quarter period, its cycle complete): ``to_sync``,
    ``station``, ``after``; per complete cycle: ``station_first_tpdo``, ``station_share``."""
    import numpy as np
    from ssi_bridge.protocol import wire

    wire_us = after_sync_wire_s(n_joints) * 1e6
    expected = len(wire.cycle_payloads(n_joints)) - 1
    t, cob = run["frames"][:, 0], run["frames"][:, 1]
    syncs = t[cob == SYNC_ID]
    is_tpdo = (cob >= TPDO_IDS[0]) & (cob < TPDO_IDS[1])
    tpdo = t[is_tpdo]
    bits = np.concatenate([[0], np.cumsum(run["frames"][is_tpdo, 2])])
    start = np.searchsorted(tpdo, syncs, side="right")
    end = np.append(np.searchsorted(tpdo, syncs[1:], side="left"), len(tpdo))
    complete = (end - start) == expected
    frames_us = (bits[end] - bits[start]) / BITRATE * 1e6
    first = np.where(complete, tpdo[np.minimum(start, len(tpdo) - 1)], 0)
    last = np.where(complete, tpdo[np.maximum(end - 1, 0)], 0)
    recv, stamp = run["recv"], run["stamp"]
    j = np.clip(np.searchsorted(syncs, stamp), 1, len(syncs) - 1)
    j = np.where(np.abs(syncs[j - 1] - stamp) < np.abs(syncs[j] - stamp), j - 1, j)
    ok = (np.abs(syncs[j] - stamp) < 0.25e9 / run["rate"]) & complete[j]
    j, recv_ok, stamp_ok = j[ok], recv[ok], stamp[ok]
    cyc = complete & (syncs >= stamp.min()) & (syncs <= stamp.max())
    return {"beyond_wire": (recv - stamp) / 1e3 - wire_us, "span": run["span"],
            "to_sync": (syncs[j] - stamp_ok) / 1e3,
            "station": (last[j] - syncs[j]) / 1e3,
            "after_station": (recv_ok - last[j]) / 1e3,
            "station_first_tpdo": (first[cyc] - syncs[cyc]) / 1e3,
            "station_share": (last[cyc] - syncs[cyc]) / 1e3 - wire_us,
            "station_beyond_frames": (last[cyc] - syncs[cyc]) / 1e3 - frames_us[cyc],
            "matched": float(ok.mean()), "wire_us": wire_us}


FIGURES = {
    "beyond_wire": "receive - header.stamp - computed SYNC->last TPDO wire time (the node "
                   "benchmark's total latency beyond the wire)",
    "station_share": "SYNC in the kernel -> the cycle's last TPDO in the kernel, minus the "
                     "computed wire time: the simulated station's part of beyond_wire",
    "station_beyond_frames": "SYNC in the kernel -> the cycle's last TPDO in the kernel, "
                             "minus the cycle's TPDOs' own wire time (their real stuffing): the "
                             "station's reaction (wake-up, SSI read, send) beyond its frames",
    "station_first_tpdo": "SYNC in the kernel -> the cycle's first TPDO in the kernel (the "
                          "station's reaction, its first frame's wire time included)",
    "after_station": "the cycle's last TPDO in the kernel -> the subscriber's receive: the "
                     "driver and DDS",
    "to_sync": "header.stamp -> the SYNC in the kernel: the node's SYNC send",
    "span": "the node's own span: the completing TPDO in the kernel -> publish() returned "
            "(ros/span_probe.py; a checkout without it has no baseline)",
}


def report(records: list[dict[str, Any]], n_joints: int,
           pairs: list[tuple[dict[str, Any], dict[str, Any]]], station: str = "new") -> None:
    """The case's records from its (new, old) run pairs: value new, baseline old;
    ``station``: whose station program ran (``old``: metrics ``node_samestation_oldstation_*``)."""
    import numpy as np

    prefix = "node_samestation_" + ("oldstation_" if station == "old" else "")
    figs = [(split(new, n_joints), split(old, n_joints)) for new, old in pairs]
    where = (f"{n_joints} joint(s) at {case_rate(n_joints):g} Hz, {BITRATE} bit/s, wire "
             f"{figs[0][0]['wire_us']:.0f} us; one station process of the {station} "
             f"checkout for all runs; value = this checkout's node, baseline = the other "
             f"checkout's; median of "
             f"{len(pairs)} alternating pairs in one sitting; samples matched to their SYNC: "
             f"{min(min(a['matched'], b['matched']) for a, b in figs):.3f} or more; machine "
             "shared with other benchmarks")
    for key, what in FIGURES.items():
        if not all(len(new[key]) for new, _ in figs):
            continue  # a node that wrote no spans
        for q in (50, 99):
            a = [float(np.percentile(new[key], q)) for new, _ in figs]
            b = [float(np.percentile(old[key], q)) if len(old[key]) else 0.0
                 for _, old in figs]
            rec: dict[str, Any] = {"metric": f"{prefix}{n_joints}enc_{key}_p{q}_us",
                         "value": round(statistics.median(a), 1), "unit": "us",
                         "baseline": round(statistics.median(b), 1) if all(b) else None,
                         "runs": [[round(x, 1), round(y, 1)] for x, y in zip(a, b)],
                         "note": f"{what}; {where}"}
            if all(y > 0 for y in b) and key not in ("station_share",):
                rec["ratio"] = round(statistics.median(x / y for x, y in zip(a, b)), 3)
            if key == "beyond_wire" and "ratio" in rec:
                rec["goal"] = "ratio <= 1.0 (no worse than the other checkout)"
                rec["goal_met"] = rec["ratio"] <= 1.0
            emit(records, rec)
    for key, unit in (("cpu_s_per_s", "s/s"), ("rate_hz", "Hz")):
        a, b = [n[key] for n, _ in pairs], [o[key] for _, o in pairs]
        emit(records, {"metric": f"{prefix}{n_joints}enc_{key}",
                       "value": round(statistics.median(a), 3), "unit": unit,
                       "baseline": round(statistics.median(b), 3),
                       "ratio": round(statistics.median(x / y for x, y in zip(a, b)), 3),
                       "note": f"the node process (its CPU s per s, or messages per s); {where}"})


def run_case(records: list[dict[str, Any]], n_joints: int, old: Path, runs: int, work: Path,
             station: str = "new") -> None:
    """One case: one station (of the ``station`` checkout, in its own environment), the two
    nodes alternating, :func:`report` at the end."""
    domain = domain_id()
    env = dds_env(domain)
    extra = {k: v for k, v in env.items() if k.startswith(DDS_KEYS)}
    envs = {"new": {**checkout_env(REPO), **extra}, "old": {**checkout_env(old), **extra}}
    roots = {"new": REPO, "old": old}
    channel = real_params(f"samestation_{domain}_{n_joints}")["bus.channel"]
    station_file = work / f"station{n_joints}.yaml"
    cmds = {v: node_command(roots[v], envs[v], n_joints, channel, work, f"{v}{n_joints}")
            for v in roots}
    own = cmds[station]  # the station reads its node's params file (simulation switch named)
    station_file.write_text(Path(own[own.index("--params-file") + 1]).read_text())
    results: dict[str, list[dict[str, Any]]] = {"new": [], "old": []}
    st_env = env if station == "new" else envs["old"]
    with station_process(roots[station], station_file, channel, st_env,
                         work / f"station{n_joints}.log", ("--priority", STATION_PRIORITY)):
        for r in range(runs):
            for v in (("new", "old") if r % 2 == 0 else ("old", "new")):
                results[v].append(one_run(f"{v}{n_joints}r{r}", cmds[v], channel, env, work,
                                          case_rate(n_joints)))
    report(records, n_joints, list(zip(results["new"], results["old"])), station)


def run_all(records: list[dict[str, Any]], old: Path, runs: int = RUNS,
            cases: tuple[int, ...] = CASES, station: str = "new") -> None:
    """Every case against the checkout ``old``, the ``station`` checkout's station program
    (``new``: this one's) answering; a case that fails is an ``error`` record. The records
    also go to bench/results/node_samestation_<UTC time>.jsonl."""
    with tempfile.TemporaryDirectory(prefix="bench_samestation_") as tmp:
        for n in cases:
            try:
                run_case(records, n, old.resolve(), runs, Path(tmp), station)
            except Exception as err:  # noqa: BLE001 - a benchmark reports, never fails
                emit(records, {"metric": f"node_samestation_{n}enc",
                               "error": f"{type(err).__name__}: {err}"})
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y%m%dT%H%MZ")
    save(records, RESULTS.parent / f"node_samestation_{stamp}.jsonl")


def main(argv: list[str] | None = None) -> int:
    """Run the comparison (:func:`run_all`) and append its records to
    bench/results/latest.jsonl; always 0 (2 for a bad command line)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("old", type=Path, help="the other checkout (set up: .venv, install/)")
    p.add_argument("--runs", type=int, default=RUNS, help=f"A/B pairs per case ({RUNS})")
    p.add_argument("--cases", default=",".join(map(str, CASES)), help="encoders per case")
    p.add_argument("--station", choices=("new", "old"), default="new",
                   help="whose station program answers both nodes (default new: this "
                        "checkout's; old: the other checkout's, in its environment)")
    args = p.parse_args(argv)
    records: list[dict[str, Any]] = []
    run_all(records, args.old, args.runs, tuple(int(c) for c in args.cases.split(",")),
            args.station)
    save(records)
    return 0


if __name__ == "__main__":
    sys.exit(main())
