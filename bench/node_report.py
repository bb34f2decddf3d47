"""The node benchmark's figures against the bare and the floor publisher, and the loaded run.

Each figure is a benchlib record, printed at once and kept for ``save``:

* :func:`report`: ``node_<N>enc[_pinned]_<key>`` for every key of :data:`NOTES` (unit
  :data:`UNITS`, the goals of :data:`GOALS` on the ratio) against the bare publisher, and
  ``node_<N>enc_latency_beyond_wire_p50_us`` / ``_p99_us``: receive - header.stamp minus the
  computed SYNC -> last TPDO wire time, against the bare publisher's latency (goal p99 <= 1.2x)
* :func:`report_floor`: ``node_<N>enc_latency_floor_p50_us`` / ``_p99_us``, the floor
  publisher against the bare one, and ``node_<N>enc_latency_beyond_wire_vs_floor_p50_us`` /
  ``_p99_us``, the node's latency beyond the wire against the floor: what the bridge adds on
  top of what any receiving rclpy node adds
* :func:`report_loaded`: ``node_<N>enc_loaded_cycles_missed_fraction``, ``_spurious_faults``
  (EMCY / "silent" in the node log) and ``_stamp_inversions`` of the run beside two CPU burners
"""

from __future__ import annotations

from benchlib import emit_record as emit
from node_baselines import FLOOR_PRIORITY
from node_cases import BITRATE, beyond_wire_us, case_rate
from node_procs import subscriber_scheduling

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


def report(records: list[dict], n_joints: int, node: dict, bare: dict, label: str = "") -> None:
    """The node's window (a :func:`node_measure.measure` result) against the bare
    publisher's; ``label`` "_pinned" for the node pinned to one CPU (then no beyond-the-wire
    figures)."""
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
