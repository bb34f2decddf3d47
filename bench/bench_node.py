"""Benchmark: ssi_bridge_node's joint_states against a bare rclpy publisher (``make bench
ONLY=node``); the entry point, whose parts live in the ``node_*.py`` modules beside it.

For 1 and 8 encoders (``node_cases.py``: joints j1..jN on slots 1..N) the installed
``ssi_bridge_node`` runs on a simulated 1 Mbit/s CAN wire at 1 kHz (1 encoder) or at the
highest rate that wire allows for 8 slots (docs/canopen.md table: 480 Hz), and a subscriber
in another process records the receive wall time and ``header.stamp`` of every JointState
(``node_measure.py``: ~2 s of warm-up, ~5 s measured per publisher). The same subscriber
program then measures the baselines of ``node_baselines.py``, in the same run and the same DDS
domain: a bare rclpy timer publisher of an equally sized JointState at the same rate, and the
floor publisher (an rclpy thread woken by another process's datagram, publishing at once).

In this order, each part's figures printed as it ends; for each case (1, then 8 encoders):

1. the driver alone (``node_driver.py``, ``node_<N>enc_driver[_real]_*`` and
   ``node_<N>enc_station_child_cpu_s_per_s``): medians of three runs in one sitting; the
   real-deployment node against the I/O floor (``node_iofloor.py``, the driver's bus I/O
   alone: ``node_<N>enc_driver_real_*_vs_io_floor``, ``node_<N>enc_io_floor_*``)
2. the first of those runs against the bare and the floor publisher (``node_report.py``):
   ``node_<N>enc_rate_hz`` (goal >= 0.99x bare), ``_jitter_p99_us``, ``_latency_p50_us`` /
   ``_p99_us`` (goal p99 <= 1.2x bare), ``_cpu_s_per_s`` (the node's process alone, not its
   station child), ``_latency_beyond_wire_p50_us`` / ``_p99_us``, ``_latency_floor_*`` and
   ``_latency_beyond_wire_vs_floor_*``; for 8 encoders also the node pinned to one CPU
   (``node_8enc_pinned_*``, not with ``BENCH_NODE_ONLY=driver``, which stops after these two)

then, once:

3. one master driving 4 stations x 2 slots against 1 x 8 (``node_stations.py``,
   ``node_4stations_2slots*``; ``BENCH_NODE_ONLY=stations`` runs only this part)
4. the loaded run (1 encoder, 1 kHz, two CPU-burning processes beside it, killed by PID at the
   end): ``node_1enc_loaded_cycles_missed_fraction``, ``_spurious_faults``,
   ``_stamp_inversions``
5. the live view's cost (``node_liveview.py``, ``node_1enc_liveview_*``)
6. without ``BENCH_NODE_ONLY``: the service-call burst (``service_burst.py``)

``BENCH_NODE_ONLY=samestation BENCH_NODE_OLD=<another checkout, set up>`` runs only
``node_samestation.py``: this checkout's node and the other's, driven in turn by one station
process (``node_samestation_<N>enc_*``).

QoS on every side is the node's: KEEP_LAST 10, RELIABLE, VOLATILE. DDS is isolated: a unique
ROS_DOMAIN_ID and ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST. Every subprocess is stopped by PID
(``node_procs.py``).

Prints one JSON object per line and appends them to bench/results/latest.jsonl; never fails
(an error becomes a line with "error"; exit status 0).
"""

from __future__ import annotations

import os
import sys
import tempfile
import traceback
from pathlib import Path

from benchlib import emit_record as emit
from benchlib import save
from node_cases import CASES, NODE_EXE, NODE_NS, PIN_CPU, case_rate, node_cmd
from node_driver import DRIVER_RUNS, driver_run, report_driver, report_io_floor
from node_liveview import measure_liveview, report_liveview
from node_measure import measure
from node_procs import burners, dds_env, domain_id
from node_report import report, report_floor, report_loaded
from node_stations import run_stations

HERE = Path(__file__).resolve().parent


def run(records: list[dict]) -> None:
    """Every part of the node benchmark that ``BENCH_NODE_ONLY`` selects (all when unset); a
    case or part that raises becomes an ``error`` record and the next one runs.

    :raises RuntimeError: the installed node is missing (``make setup`` not run)
    """
    if os.environ.get("BENCH_NODE_ONLY") == "samestation":
        from node_samestation import run_all  # node_samestation.py: the other checkout's node
        if not os.environ.get("BENCH_NODE_OLD"):
            raise RuntimeError("BENCH_NODE_OLD must name the other checkout (set up)")
        run_all(records, Path(os.environ["BENCH_NODE_OLD"]))
        return
    if os.environ.get("BENCH_NODE_ONLY") == "stations":
        domain = domain_id()
        with tempfile.TemporaryDirectory(prefix="bench_node_") as tmp:
            run_stations(records, domain, dds_env(domain), Path(tmp))
        return
    if not NODE_EXE.exists():
        raise RuntimeError(f"{NODE_EXE} missing: run `make setup`")
    only = os.environ.get("BENCH_NODE_ONLY", "")
    domain = domain_id()
    env = dds_env(domain)
    plain: dict[int, dict] = {}
    with tempfile.TemporaryDirectory(prefix="bench_node_") as tmp:
        work = Path(tmp)
        for n in CASES:
            try:
                runs = [driver_run(n, r, domain, env, work) for r in range(DRIVER_RUNS)]
                report_driver(records, n, [(nd, b, f) for nd, b, f, _, _ in runs])
                report_driver(records, n, [(r, b, f) for _, b, f, r, _ in runs], "real")
                report_io_floor(records, n, [(r, b, f, io) for _, b, f, r, io in runs])
                node, bare, floor, _, _ = runs[0]
                report(records, n, node, bare)
                report_floor(records, n, node, bare, floor)
                plain[n] = node
                if only == "driver":
                    continue
                if n == max(CASES):
                    pinned = measure(f"node{n}pin", node_cmd(n, domain, work, {
                        "cpu_affinity": [PIN_CPU]}), f"{NODE_NS}/joint_states", env, work,
                        case_rate(n))
                    report(records, n, pinned, bare, "_pinned")
            except Exception as err:  # noqa: BLE001 - a benchmark reports, never fails
                emit(records, {"metric": f"node_{n}enc", "error": f"{type(err).__name__}: {err}",
                               "note": traceback.format_exc(limit=3)[-800:]})
        if only == "driver":
            return
        try:
            run_stations(records, domain, env, work)
        except Exception as err:  # noqa: BLE001 - a benchmark reports, never fails
            emit(records, {"metric": "node_stations", "error": f"{type(err).__name__}: {err}",
                           "note": traceback.format_exc(limit=3)[-800:]})
        load = burners(2)
        try:
            node = measure("node1loaded", node_cmd(1, domain, work), f"{NODE_NS}/joint_states",
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
                report_liveview(records, measure_liveview(domain, env, work), plain[1])
            except Exception as err:  # noqa: BLE001
                emit(records, {"metric": "node_1enc_liveview",
                               "error": f"{type(err).__name__}: {err}",
                               "note": traceback.format_exc(limit=3)[-800:]})


def main() -> int:
    """Run the benchmark, then (without ``BENCH_NODE_ONLY``) the service burst; append every
    record to the results file. Always 0: a failure is an ``error`` record."""
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


#: what other benchmarks import from here (``from bench_node import case_rate``)
__all__ = ["case_rate", "main", "run"]

if __name__ == "__main__":
    sys.exit(main())
