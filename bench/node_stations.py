"""One master driving several stations: 4 stations x 2 slots against 1 station x 8 slots.

Both carry 12 TPDOs + 1 SYNC per cycle (8 images, 4 position pairs), so the wire time is the
same; the cost should follow the slots, not the stations (ratio ~1). Figures:
``node_4stations_2slots[_master_only]_<key>`` for the CPU, latency p50 / p99 and rate
(``BENCH_NODE_ONLY=stations`` runs only this part).
"""

from __future__ import annotations

from pathlib import Path

from benchlib import emit_record as emit
from node_cases import NODE_EXE, NODE_NS
from node_measure import measure
from node_report import NOTES, UNITS

#: stations case: 13 frames per cycle (SYNC + 8 image + 4 position TPDOs), about
#: 1.6 ms of wire at 1 Mbit/s with worst-case stuffing, so 400 Hz loads the wire ~65 %
STATIONS_RATE_HZ = 400.0
STATIONS_BITRATE = 1_000_000


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

    ``virtual``: the simulated stations run in the node's process (each its own bus receiver
    of every frame, as each real device has its own CAN controller), so the node's CPU
    includes them; ``udp_multicast``: one child process per station, the node's CPU is the
    master's alone.

    :raises RuntimeError: as :func:`node_measure.measure`
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
