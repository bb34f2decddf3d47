"""One measurement of the node benchmark: a publisher and the subscriber, one window.

:func:`measure` starts a publisher (the node, or a baseline of ``node_baselines.py``) and a
subscriber in another process (``bench/node_subscriber.py``, which records the receive wall
time and ``header.stamp`` of every JointState), waits for the first message, lets
:data:`WARMUP_S` pass and measures :data:`MEASURE_S`: the rate, the jitter, the latency
(receive wall time - header.stamp), the publisher's CPU and its children's, and, where the
publisher writes them, its spans (``ssi_bridge/ros/span_probe.py``).
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from benchlib import cpu_seconds
from node_cases import RATE_HZ
from node_procs import cpu_of, descendants, die_with_parent, real_time_subscriber, stop, tail

HERE = Path(__file__).resolve().parent
SUBSCRIBER = HERE / "node_subscriber.py"
WARMUP_S = 2.0
MEASURE_S = 5.0
STARTUP_TIMEOUT_S = 20.0
#: the node's span probe (ssi_bridge/ros/span_probe.py): set in the measured node's environment
SPAN_ENV = "SSI_BRIDGE_SPAN_LOG"


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
    ``children_cpu_s_per_s`` its child processes'. Both processes are stopped by PID before
    it returns.

    :raises RuntimeError: a process exited early, no message came within
        :data:`STARTUP_TIMEOUT_S`, the subscriber wrote nothing, or the window held fewer
        than 3 messages
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
                                   preexec_fn=real_time_subscriber)
        procs.append(sub)
        with open(pub_log, "wb") as log:
            pub = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, cwd=work,
                                   start_new_session=True,
                                   preexec_fn=die_with_parent)
        procs.append(pub)
        deadline = time.monotonic() + STARTUP_TIMEOUT_S
        while not ready.exists():
            for p, log in ((pub, pub_log), (sub, sub_log)):
                if p.poll() is not None:
                    raise RuntimeError(f"{tag}: {p.args[0]} exited {p.returncode}: {tail(log)}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"{tag}: no message on {topic} within {STARTUP_TIMEOUT_S} s; "
                                   f"publisher log: {tail(pub_log)}")
            time.sleep(0.05)
        time.sleep(WARMUP_S)
        kids = descendants(pub.pid)
        cpu0, kid0, w0, m0 = (cpu_seconds(pub.pid), cpu_of(kids), time.time_ns(),
                              time.monotonic())
        time.sleep(MEASURE_S)
        cpu1, kid1, w1, m1 = (cpu_seconds(pub.pid), cpu_of(kids), time.time_ns(),
                              time.monotonic())
        if pub.poll() is not None:
            raise RuntimeError(f"{tag}: publisher exited {pub.returncode}: {tail(pub_log)}")
        stop(sub)
        if not out.exists():
            raise RuntimeError(f"{tag}: subscriber wrote no samples: {tail(sub_log)}")
    finally:
        for p in reversed(procs):
            stop(p)

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
    log = tail(pub_log, 200_000)
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
