"""Soak benchmark: hours of recording must not cost memory or messages.

``make bench ONLY=soak`` (or ``python bench/bench_soak.py --minutes 3``) runs the installed
``ssi_bridge_node`` with the two-encoder station of ``config/ssi_bridge.yaml`` at 1 kHz for
N minutes (default 10) recording a session split every minute (``record.max_duration: 60``),
then N minutes the same without recording, in the same run. A subscriber in another process
(``bench/node_subscriber.py``) keeps the stamp of every joint_states message. Reported:

* ``soak_rss_growth``: slope of the node's RSS (sampled every 2 s after a 60 s warm-up,
  least squares) in MB per 10 minutes; goal <= 1 MB / 10 min with recording; baseline:
  without. The note adds the slope of the second half of the window: in a short run the
  first minutes still carry start-up growth that levels off
* ``soak_messages_lost``: joint_states the subscriber received inside the bag's time span
  that are not in the bag (node -> bag losses); goal 0. The note also gives the reverse
  (in the bag, not received: DDS losses), and checks every file opens as a complete MCAP
* ``soak_cycles_missed``: SYNC slots without a message at the subscriber (gaps in the
  stamps of the received joint_states, the SSI latch times: the node's missed cycles plus
  DDS drops), with recording; baseline: without. The note adds the node's own count with
  recording, from the gaps in the bag's stamps
* ``soak_bag_mb_per_min``: bag size per minute of recording, and the files it was split into
* ``soak_cpu_s_per_s``: node CPU (utime + stime) per second; baseline: without recording

Minutes, not seconds: not part of ``make test``. JSON lines as the other benchmarks, also
appended to bench/results/latest.jsonl; never fails (an error becomes a line with "error").
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
import traceback
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))
from node_cases import NODE_EXE  # noqa: E402
from node_measure import publisher_and_subscriber  # noqa: E402
import node_procs  # noqa: E402
from node_procs import dds_env, stop, tail  # noqa: E402
from benchlib import cpu_seconds, save  # noqa: E402
from benchlib import emit_record as emit  # noqa: E402

CONFIG = REPO / "config" / "ssi_bridge.yaml"
RATE_HZ = 1000.0
SPLIT_S = 60
#: start-up growth (rclpy caches, malloc arenas, the first file) settles within ~1.5 min
WARMUP_S = 60.0
SAMPLE_S = 2.0
NS = "/soak"
GOAL_RSS_MB_PER_10MIN = 1.0


def rss_mb(pid: int) -> float:
    """Resident set size of ``pid`` in MB (VmRSS)."""
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    raise RuntimeError(f"no VmRSS for {pid}")


def slope_per_10min(samples: list[tuple[float, float]]) -> float:
    """Least-squares slope of (t s, MB) samples, in MB per 600 s."""
    import numpy as np

    t = np.array([s[0] for s in samples])
    y = np.array([s[1] for s in samples])
    if len(t) < 3 or t[-1] - t[0] <= 0:
        raise RuntimeError(f"only {len(t)} RSS samples")
    return float(np.polyfit(t - t[0], y, 1)[0] * 600.0)


def half(samples: list[tuple[float, float]]) -> float:
    """RSS slope (MB/10 min) of the second half of the samples."""
    return slope_per_10min(samples[len(samples) // 2:])


def node_cmd(work: Path, tag: str, domain_id: int, record: bool) -> list[str]:
    """The installed node on the two-encoder config at 1 kHz (+ recording, split per minute)."""
    import yaml

    params: dict = {"publish_rate": RATE_HZ, "bus.channel": f"soak_{domain_id}_{tag}",
                    "storage_path": str(work / tag / "retentive.json")}
    if record:
        params.update({"record.enabled": True, "record.root": str(work / "sessions"),
                       "record.path": tag, "record.max_duration": SPLIT_S})
    pfile = work / f"params_{tag}.yaml"
    pfile.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
    return [str(NODE_EXE), "--ros-args", "--params-file", str(CONFIG), "--params-file",
            str(pfile), "-r", f"__ns:={NS}"]


def missed_cycles(stamps_ns: list[int]) -> int:
    """SYNC slots without a message: each gap of k periods between stamps misses k - 1."""
    period = 1e9 / RATE_HZ
    ordered = sorted(set(stamps_ns))
    return sum(max(0, round((b - a) / period) - 1) for a, b in zip(ordered, ordered[1:]))


def run_phase(tag: str, record: bool, minutes: float, domain_id: int, work: Path) -> dict:
    """One soak: node + subscriber for ``minutes``; RSS, CPU, received stamps, the bag."""
    env = dds_env(domain_id)
    # both scheduled as this process, as the soak has always run them
    with publisher_and_subscriber(tag, node_cmd(work, tag, domain_id, record),
                                  f"{NS}/joint_states", env, work,
                                  sub_preexec=None, pub_preexec=None) as run:
        node, pub_log = run.pub, run.pub_log
        time.sleep(WARMUP_S)
        cpu0, m0 = cpu_seconds(node.pid), time.monotonic()
        samples: list[tuple[float, float]] = []
        end = m0 + minutes * 60.0
        while time.monotonic() < end:
            samples.append((time.monotonic() - m0, rss_mb(node.pid)))
            if node.poll() is not None:
                raise RuntimeError(f"{tag}: node exited {node.returncode}: {tail(pub_log)}")
            time.sleep(max(0.0, min(SAMPLE_S, end - time.monotonic())))
        samples.append((time.monotonic() - m0, rss_mb(node.pid)))
        cpu1, m1 = cpu_seconds(node.pid), time.monotonic()
        stop(node, timeout=30.0)  # SIGINT: the node closes its bag
        if node.returncode != 0:
            raise RuntimeError(f"{tag}: node exited {node.returncode}: {tail(pub_log)}")
    with open(run.samples) as f:
        stamps = [int(line.split()[1]) for line in f if line.strip()]
    return {"rss": samples, "rss_growth": slope_per_10min(samples),
            "cpu": (cpu1 - cpu0) / (m1 - m0), "stamps": stamps, "window_s": m1 - m0,
            "bag": work / "sessions" / tag if record else None}


def bag_figures(bag: Path, received: list[int]) -> dict:
    """Compare the bag's joint_states with the subscriber's: losses both ways, files, size."""
    from mcap.reader import make_reader

    from ssi_bridge.record.metadata import read_metadata
    from ssi_bridge.record.reader import Bag

    info = read_metadata(bag)
    files = [bag / name for name in info["relative_file_paths"]]
    complete = 0
    for path in files:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
            complete += int(summary is not None and summary.statistics is not None)
    topic = f"{NS}/joint_states"
    with Bag(bag) as reader:
        recorded = [m.publish_time for _, m in reader.messages([topic])]
    own_missed = missed_cycles(recorded)
    in_bag = set(recorded)
    lo, hi = min(recorded), max(recorded)
    window = {s for s in received if lo <= s <= hi}
    return {"lost_to_bag": len(window - in_bag), "not_received": len(in_bag - set(received)),
            "recorded": len(recorded), "duplicates": len(recorded) - len(in_bag),
            "received_in_window": len(window), "files": len(files), "complete_files": complete,
            "bytes": sum(p.stat().st_size for p in files),
            "span_min": (hi - lo) / 60e9, "metadata_count": info["message_count"],
            "own_missed": own_missed}


def report(records: list[dict], on: dict, off: dict, bag: dict, minutes: float) -> None:
    dur = f"{minutes:g} min per phase at {RATE_HZ:g} Hz, two encoders (config/ssi_bridge.yaml)"
    growth, base = on["rss_growth"], off["rss_growth"]
    emit(records, {"metric": "soak_rss_growth", "value": round(growth, 3),
                   "unit": "MB/10min", "baseline": round(base, 3),
                   "ratio": round(growth / base, 3) if abs(base) > 0.05 else None,
                   "goal": f"value <= {GOAL_RSS_MB_PER_10MIN}",
                   "goal_met": growth <= GOAL_RSS_MB_PER_10MIN, "duration_min": minutes,
                   "note": f"node RSS slope with recording (split every {SPLIT_S} s); baseline: "
                           f"without recording, same run; RSS {on['rss'][0][1]:.1f} -> "
                           f"{on['rss'][-1][1]:.1f} MB (off: {off['rss'][0][1]:.1f} -> "
                           f"{off['rss'][-1][1]:.1f}); second half of the window: "
                           f"{half(on['rss']):.3f} (off: {half(off['rss']):.3f}) MB/10min; "
                           f"{dur}; lower is better"})
    emit(records, {"metric": "soak_messages_lost", "value": bag["lost_to_bag"],
                   "unit": "messages", "goal": "value == 0",
                   "goal_met": bag["lost_to_bag"] == 0 and bag["duplicates"] == 0,
                   "duration_min": minutes,
                   "note": f"joint_states received by a subscriber process inside the bag's "
                           f"span but missing from the bag; bag {bag['recorded']} "
                           f"(metadata.yaml: {bag['metadata_count']} all topics), received in "
                           f"span {bag['received_in_window']}, in bag but not received (DDS) "
                           f"{bag['not_received']}, duplicates {bag['duplicates']}; {dur}"})
    m_on, m_off = missed_cycles(on["stamps"]), missed_cycles(off["stamps"])
    emit(records, {"metric": "soak_cycles_missed", "value": m_on, "unit": "cycles",
                   "baseline": m_off, "ratio": round(m_on / m_off, 3) if m_off else None,
                   "duration_min": minutes,
                   "note": f"SYNC slots without a joint_states at the subscriber (gaps in "
                           f"the received stamps: the node's missed cycles plus DDS drops), "
                           f"with recording; baseline: without; of ~"
                           f"{int(on['window_s'] * RATE_HZ)} cycles per phase (+ warm-up); "
                           f"the node's own with recording (gaps in the bag's stamps over "
                           f"{bag['span_min']:.2f} min): {bag['own_missed']}; {dur}; lower is "
                           f"better"})
    emit(records, {"metric": "soak_bag_mb_per_min",
                   "value": round(bag["bytes"] / 1e6 / max(bag["span_min"], 1e-9), 3),
                   "unit": "MB/min", "duration_min": minutes,
                   "note": f"{bag['files']} files ({bag['complete_files']} complete MCAP with "
                           f"summary), {bag['bytes'] / 1e6:.1f} MB over {bag['span_min']:.2f} "
                           f"min of recording, zstd chunks; {dur}"})
    emit(records, {"metric": "soak_cpu_s_per_s", "value": round(on["cpu"], 3), "unit": "s/s",
                   "baseline": round(off["cpu"], 3), "ratio": round(on["cpu"] / off["cpu"], 3),
                   "duration_min": minutes,
                   "note": f"node process CPU per second with recording; baseline: without, "
                           f"same run; {dur}; lower is better"})


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--minutes", type=float,
                        default=float(os.environ.get("SOAK_MINUTES", "10")),
                        help="minutes per phase (recording, then not); default 10 "
                             "(or $SOAK_MINUTES: make bench ONLY=soak SOAK_MINUTES=3)")
    args = parser.parse_args(argv)
    records: list[dict] = []
    try:
        if not NODE_EXE.exists():
            raise RuntimeError(f"{NODE_EXE} missing: run `make setup`")
        domain_id = node_procs.domain_id()
        with tempfile.TemporaryDirectory(prefix="bench_soak_") as tmp:
            work = Path(tmp)
            on = run_phase("rec", True, args.minutes, domain_id, work)
            off = run_phase("norec", False, args.minutes, domain_id, work)
            assert on["bag"] is not None
            report(records, on, off, bag_figures(on["bag"], on["stamps"]), args.minutes)
    except Exception as err:  # noqa: BLE001 - a benchmark reports, never fails
        emit(records, {"metric": "soak", "error": f"{type(err).__name__}: {err}",
                       "note": traceback.format_exc(limit=3)[-800:]})
    save(records)
    return 0


if __name__ == "__main__":
    sys.exit(main())
