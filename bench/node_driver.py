"""The driver alone: its own latency span and CPU, medians of :data:`DRIVER_RUNS` runs.

Each case runs :data:`DRIVER_RUNS` times in one sitting (:func:`driver_run`), each run the
node with its simulated station, the node as a real deployment runs it, the bare and the
floor publisher, one after the other; :func:`report_driver` prints the median of the runs'
ratios (each run against its own baselines), with the runs:

* ``node_<N>enc_driver_latency_p50_us`` / ``_p99_us``: the node's span per cycle, from the
  kernel receive timestamp of the frame that completed it to ``publish()`` returning (the
  node writes it when ``SSI_BRIDGE_SPAN_LOG`` names a file, ``ssi_bridge/ros/span_probe.py``),
  against the floor publisher's span, datagram in the kernel (``SO_TIMESTAMPNS``) to
  ``publish()`` returning (goal p99 <= 1.3x)
* ``node_<N>enc_driver_cpu_s_per_s``: the node's process alone against the bare publisher
  (goal <= 1.5x); ``node_<N>enc_station_child_cpu_s_per_s``: its station child, for the record
* ``node_<N>enc_driver_real_*``: the same figures with the node as a real deployment runs it
  (``real_station.py``: ``simulation.enabled:=false`` on udp_multicast against the
  ``station`` program started apart), so the node process holds the driver alone; the plain
  ``driver_*`` node has the simulation on, its own bus end the simulated wire (its SYNC paced
  at bit time in the node process)
* ``node_<N>enc_driver_real_cpu_vs_io_floor`` and ``_latency_p50_us_vs_io_floor`` /
  ``_p99_us_vs_io_floor`` (:func:`report_io_floor`): the real-deployment node against the I/O
  floor (``node_iofloor.py``: the driver's bus I/O, one SYNC sent and the cycle's TPDOs
  received, and publishing, nothing else), i.e. how much of the node's CPU and span is its
  own code rather than the transport any driver on this bus pays; and the I/O floor's own
  ``node_<N>enc_io_floor_cpu_s_per_s`` (against the bare publisher) and
  ``_io_floor_latency_p50_us`` / ``_p99_us`` (its span against the floor's), for the record
"""

from __future__ import annotations

import statistics
from pathlib import Path

from benchlib import emit_record as emit
from node_baselines import BARE_TOPIC, FLOOR_TOPIC, bare_cmd, floor_cmd
from node_cases import BITRATE, NODE_NS, REPO, case_rate, node_cmd
from node_iofloor import IO_FLOOR_TOPIC, io_floor_cmd
from node_measure import measure

#: runs of each case for the driver-only figures (medians of the runs' ratios)
DRIVER_RUNS = 3
#: goals of the driver-only figures: the driver's own latency and CPU
DRIVER_GOALS = {"latency_p99": 1.3, "cpu": 1.5}

#: the two ways the driver-only figures run the node: metric label, what the node process holds
DRIVER_SETUPS = {
    "sim": ("", "node with simulation.enabled (its station a child process on udp_multicast; "
                "the node's own bus end is the simulated wire, its SYNC paced at bit time in "
                "the node process)"),
    "real": ("_real", "node as a real deployment runs it: simulation.enabled:=false on "
                      "udp_multicast, the `station` program a separate process (the node "
                      "process holds the driver alone)"),
}


def driver_run(n_joints: int, run: int, domain_id: int, env: dict[str, str],
               work: Path) -> tuple[dict, dict, dict, dict, dict]:
    """One run of a case: the node with its simulated station, the node as a real deployment
    runs it (``real_station.py``), the bare and the floor publisher and the I/O floor
    (``node_iofloor.py``), one after the other, the nodes and the floors writing their spans.
    Returns (node, bare, floor, real, io_floor), each a :func:`node_measure.measure` result.

    :raises RuntimeError: as :func:`node_measure.measure`, or the station program did not
        start
    """
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
    spans = work / f"io_floor{n_joints}r{run}.spans"
    io = measure(f"io_floor{n_joints}r{run}", io_floor_cmd(n_joints, spans), IO_FLOOR_TOPIC,
                 env, work, rate, spans=spans, span_env=False)
    return node, bare, floor, real, io


def report_driver(records: list[dict], n_joints: int, runs: list[tuple[dict, dict, dict]],
                  setup: str = "sim") -> None:
    """The driver alone, medians of the runs' ratios (each run against its own baselines).

    ``runs``: (node, bare, floor) per run; ``setup``: a key of :data:`DRIVER_SETUPS`.
    Latency: the node's span from the kernel receive time of the frame that completed a
    cycle to ``publish()`` returning (``ros/span_probe.py``) against the floor publisher's
    same span (datagram in the kernel to ``publish()`` returning). CPU: the node's process
    alone (not its station child) against the bare publisher's. Runs without spans on either
    side give an ``error`` record for the latency.
    """
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


def _median_ratio(values: list[float], bases: list[float]) -> dict:
    """value, baseline (medians) and ratio (the median of the runs' ratios) of paired runs."""
    ratios = [a / b for a, b in zip(values, bases) if b]
    return {"value": round(statistics.median(values), 3 if max(values) < 10 else 1),
            "baseline": round(statistics.median(bases), 3 if max(bases) < 10 else 1),
            "ratio": round(statistics.median(ratios), 3) if ratios else None,
            "runs": [round(r, 3) for r in ratios]}


def report_io_floor(records: list[dict], n_joints: int,
                    runs: list[tuple[dict, dict, dict, dict]]) -> None:
    """The real-deployment node against the I/O floor, and the I/O floor against the bare
    publisher (CPU) and the floor (span); medians as :func:`report_driver`.

    ``runs``: (real node, bare, floor, I/O floor) per run. No goals: these figures say how
    much of the node's CPU and span is the bus I/O any driver on this bus pays.
    """
    import numpy as np

    where = (f"{n_joints} joint(s) at {case_rate(n_joints):g} Hz, {BITRATE} bit/s; median of "
             f"{len(runs)} runs in one sitting, each against its own baselines; I/O floor "
             f"received {statistics.median(io['rate_hz'] for *_, io in runs):.0f} msg/s")
    io_what = ("I/O floor = an rclpy node doing the driver's bus I/O only (node_iofloor.py: a "
               "paced SCHED_FIFO thread sends one SYNC datagram a cycle to the udp_multicast "
               "group, a station process answers with the cycle's frames at their wire "
               "spacing, the receive thread receives each and publishes on the last)")
    real_cpu = [r["cpu_s_per_s"] for r, _, _, _ in runs]
    io_cpu = [io["cpu_s_per_s"] for *_, io in runs]
    emit(records, {"metric": f"node_{n_joints}enc_driver_real_cpu_vs_io_floor", "unit": "s/s",
                   **_median_ratio(real_cpu, io_cpu),
                   "note": "utime+stime of the real-deployment node's process per s; baseline "
                           f"= the I/O floor's process (its station not counted); {io_what}; "
                           f"{where}"})
    emit(records, {"metric": f"node_{n_joints}enc_io_floor_cpu_s_per_s", "unit": "s/s",
                   **_median_ratio(io_cpu, [b["cpu_s_per_s"] for _, b, _, _ in runs]),
                   "floor_cpu_s_per_s": round(statistics.median(
                       f["cpu_s_per_s"] for _, _, f, _ in runs), 3),
                   "note": f"the I/O floor's process CPU per s; baseline = bare rclpy timer "
                           f"publisher; {io_what}; {where}"})
    usable = [(r, f, io) for r, _, f, io in runs if len(r["span"]) and len(io["span"])]
    for q in (50, 99):
        if not usable:
            emit(records, {"metric": f"node_{n_joints}enc_driver_real_latency_p{q}_us_vs_io_floor",
                           "error": "no span records (the node or the I/O floor wrote none)"})
            continue
        real = [float(np.percentile(r["span"], q)) for r, _, _ in usable]
        io = [float(np.percentile(i["span"], q)) for _, _, i in usable]
        emit(records, {"metric": f"node_{n_joints}enc_driver_real_latency_p{q}_us_vs_io_floor",
                       "unit": "us", **_median_ratio(real, io),
                       "note": "the real-deployment node's span (kernel receive time of the "
                               "frame that completed a cycle -> publish() returned); baseline "
                               f"= the I/O floor's same span; {io_what}; {where}"})
        if all(len(f["span"]) for _, f, _ in usable):
            emit(records, {"metric": f"node_{n_joints}enc_io_floor_latency_p{q}_us",
                           "unit": "us",
                           **_median_ratio(io, [float(np.percentile(f["span"], q))
                                                for _, f, _ in usable]),
                           "note": "the I/O floor's span (kernel receive time of a cycle's "
                                   "last frame -> publish() returned); baseline = the floor "
                                   f"publisher's span; {io_what}; {where}"})
