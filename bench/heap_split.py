"""The node's recording load without ROS, to compare C-heap growth of bag-writer variants.

``python bench/heap_split.py --minutes 3 --split 20`` writes what the node records with two
encoders at 1 kHz (one JointState and one Status per cycle, from one "cycle" thread, paced
by the wall clock; a DiagnosticArray every second from a second thread) into a
:class:`BagRecorder` split every ``--split`` s, and prints one JSON line per ``--sample`` s:
RSS, glibc's ``mallinfo2`` (in use, free, heap), RSS by region (``tools/memprobe.py``) and
the files written. At the end it prints the least-squares slopes (MB per 10 min) of each
after ``--warmup`` s (``--trace``: and the Python heap's largest growths, tracemalloc).
Like the node it limits the malloc arenas and fixes the mmap threshold (``record/heap.py``). Why: the node's RSS grew at
every split while the Python heap stayed flat (docs/recording.md, "Memory over hours"); this
reproduces that in minutes and, run twice side by side (e.g. one with ``PYTHONPATH`` on an
older tree), compares two variants on the same machine at the same time.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np


def rss_mb() -> float:
    """This process's resident set size (MB)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def slope(samples: list[tuple[float, float]]) -> float:
    """Least-squares slope of (s, MB) in MB per 10 min."""
    if len(samples) < 3:
        return float("nan")
    t, y = np.array(samples).T
    return float(np.polyfit(t, y, 1)[0] * 600.0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--minutes", type=float, default=3.0)
    parser.add_argument("--split", type=float, default=20.0, help="record.max_duration (s)")
    parser.add_argument("--rate", type=float, default=1000.0, help="cycles per second")
    parser.add_argument("--sample", type=float, default=5.0)
    parser.add_argument("--warmup", type=float, default=30.0)
    parser.add_argument("--compression", default="zstd")
    parser.add_argument("--label", default="")
    parser.add_argument("--trace", action="store_true",
                        help="tracemalloc: print the Python heap's largest growths after the "
                             "warm-up (slow)")
    parser.add_argument("--no-record", action="store_true",
                        help="build and serialize the messages but write nothing (baseline)")
    args = parser.parse_args(argv)

    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from sensor_msgs.msg import JointState

    from ssi_bridge.record import cdr, heap
    from ssi_bridge.record.bag import BagRecorder
    from ssi_bridge.tools.memprobe import malloc_figures, regions
    from ssi_bridge_msgs.msg import ChannelStatus, Status

    heap.limit_malloc_arenas()
    if hasattr(heap, "fix_mmap_threshold"):   # as the node does (an older tree: not yet)
        heap.fix_mmap_threshold()
    if args.trace:
        import tracemalloc
        tracemalloc.start(3)
    first = None
    libc = heap.libc()
    stop = threading.Event()
    with tempfile.TemporaryDirectory(prefix="heap_split_") as tmp:
        rec = BagRecorder.open(Path(tmp) / "bag", compression=args.compression,
                               metadata={"variant": args.label}, max_duration_s=args.split)
        rec.add_topic("/soak/joint_states", "sensor_msgs/msg/JointState")
        rec.add_topic("/soak/ssi_bridge/status", "ssi_bridge_msgs/msg/Status")
        rec.add_topic("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")
        counts = [0]

        def write(topic: str, msg: object, log_time_ns: int) -> None:
            """Into the bag; with --no-record only serialized."""
            if args.no_record:
                cdr.serialize(msg)
            else:
                rec.write(topic, msg, log_time_ns)

        def cycle() -> None:
            """One JointState + Status per period, as the node's cycle thread."""
            period = 1.0 / args.rate
            due = time.monotonic()
            i = 0
            while not stop.is_set():
                now_ns = time.time_ns()
                js = JointState(name=["shoulder", "carriage"], position=[i * 1e-3, 0.5],
                                velocity=[0.1, 0.01])
                js.header.stamp.sec, js.header.stamp.nanosec = divmod(now_ns, 10**9)
                js.header.frame_id = "station"
                st = Status(header=js.header, channels=[
                    ChannelStatus(joint="shoulder", raw=i & 0xFFFFFF, frame=i),
                    ChannelStatus(joint="carriage", raw=(7 * i) & 0xFFFFFF, frame=i)])
                write("/soak/joint_states", js, now_ns)
                write("/soak/ssi_bridge/status", st, now_ns)
                counts[0] += 2
                i += 1
                due += period
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                elif delay < -0.1:
                    due = time.monotonic()   # fell behind (loaded machine): do not burst

        def diagnostics() -> None:
            """One DiagnosticArray per second, as the node's diagnostics timer."""
            while not stop.wait(1.0):
                msg = DiagnosticArray(status=[DiagnosticStatus(
                    name=f"ssi_bridge: {j}", message="OK", hardware_id="station",
                    values=[KeyValue(key=f"k{k}", value=str(k * 1.5)) for k in range(12)])
                    for j in ("shoulder", "carriage", "bus")])
                write("/diagnostics", msg, time.time_ns())
                counts[0] += 1

        threads = [threading.Thread(target=cycle, name="cycle", daemon=True),
                   threading.Thread(target=diagnostics, name="diag", daemon=True)]
        for t in threads:
            t.start()
        t0 = time.monotonic()
        rss: list[tuple[float, float]] = []
        series: dict[str, list[tuple[float, float]]] = {}
        while (t := time.monotonic() - t0) < args.minutes * 60:
            time.sleep(args.sample)
            t = time.monotonic() - t0
            m = malloc_figures(libc) if libc is not None else {}
            row = {"label": args.label, "t": round(t, 1), "rss_mb": round(rss_mb(), 3),
                   "msgs_per_s": round(counts[0] / t, 1), "files": len(rec.files),
                   **{k: round(v, 3) for k, v in (m | regions()).items()
                      if isinstance(v, float)}}
            print(json.dumps(row), flush=True)
            if t >= args.warmup:
                if args.trace and first is None:
                    first = tracemalloc.take_snapshot()
                rss.append((t, row["rss_mb"]))
                for key, value in row.items():
                    if key.endswith("_mb") and key != "rss_mb":
                        series.setdefault(key, []).append((t, value))
        if first is not None:
            for stat in tracemalloc.take_snapshot().compare_to(first, "traceback")[:8]:
                print(f"# {stat.size_diff / 1024:+.1f} kB {stat.count_diff:+d}: "
                      + " < ".join(f"{f.filename.rsplit('/', 2)[-1]}:{f.lineno}"
                                   for f in stat.traceback), flush=True)
        stop.set()
        for t in threads:
            t.join()
        summary = rec.close()
        print(json.dumps({"label": args.label, "result": True,
                          "rss_slope": round(slope(rss), 3),
                          **{f"{k}_slope": round(slope(v), 3) for k, v in series.items()},
                          "messages": summary.message_count, "files": len(summary.files),
                          "msgs_per_s": round(summary.message_count
                                              / (time.monotonic() - t0), 1)}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
