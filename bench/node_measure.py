"""One measurement of the node benchmark: a publisher and the subscriber, one window.

:func:`measure` starts a publisher (the node, or a baseline of ``node_baselines.py``) and a
subscriber in another process (``bench/node_subscriber.py``, which records the receive wall
time and ``header.stamp`` of every JointState), waits for the first message, lets
:data:`WARMUP_S` pass and measures :data:`MEASURE_S`: the rate, the jitter, the latency
(receive wall time - header.stamp), the publisher's CPU and its children's, and, where the
publisher writes them, its spans (``ssi_bridge/ros/span_probe.py``). Benchmarks that measure
something else of a publisher with its subscriber running start the two with
:func:`publisher_and_subscriber`.
"""

from __future__ import annotations

import contextlib
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
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


def wait_for(path: Path, procs: list[tuple[subprocess.Popen, Path]], what: str,
             timeout: float = STARTUP_TIMEOUT_S) -> None:
    """Wait until ``path`` exists (a process's sign that it is ready).

    :raises RuntimeError: one of ``procs`` (a process, its log) exited first (with its log's
        tail), or ``timeout`` s passed (with the first process's log's tail)
    """
    deadline = time.monotonic() + timeout
    while not path.exists():
        for p, log in procs:
            if p.poll() is not None:
                args = [str(a) for a in p.args] if isinstance(p.args, list) else [str(p.args)]
                name = Path(args[1]).name if args[0] == sys.executable else args[0]
                raise RuntimeError(f"{what}: {name} exited {p.returncode}: {tail(log)}")
        if time.monotonic() > deadline:
            raise RuntimeError(f"{what}: nothing within {timeout} s; log: {tail(procs[0][1])}")
        time.sleep(0.05)


@dataclass(frozen=True)
class Running:
    """A publisher and the subscriber of :func:`publisher_and_subscriber`, both running."""

    pub: subprocess.Popen
    sub: subprocess.Popen
    #: the subscriber's records, one line a message: receive wall time (ns), header.stamp (ns)
    samples: Path
    pub_log: Path
    sub_log: Path


@contextlib.contextmanager
def publisher_and_subscriber(
        tag: str, cmd: list[str], topic: str, env: dict[str, str], work: Path, *,
        sub_preexec: Callable[[], None] | None = real_time_subscriber,
        pub_preexec: Callable[[], None] | None = die_with_parent) -> Iterator[Running]:
    """The subscriber on ``topic`` and the publisher ``cmd`` started (files ``<tag>.*`` in
    ``work``), the block run once the first message arrived; at its end the subscriber is
    stopped and must have written its samples. Both are stopped by PID however the block ends.
    ``sub_preexec`` / ``pub_preexec``: their preexec_fn (None: scheduled as this process).

    :raises RuntimeError: as :func:`wait_for`, or the subscriber wrote no samples
    """
    samples, ready = work / f"{tag}.samples", work / f"{tag}.ready"
    pub_log, sub_log = work / f"{tag}.pub.log", work / f"{tag}.sub.log"
    procs: list[subprocess.Popen] = []
    try:
        with open(sub_log, "wb") as log:
            sub = subprocess.Popen([sys.executable, str(SUBSCRIBER), topic, str(samples),
                                    str(ready)], stdout=log, stderr=subprocess.STDOUT, env=env,
                                   cwd=work, start_new_session=True, preexec_fn=sub_preexec)
        procs.append(sub)
        with open(pub_log, "wb") as log:
            pub = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, cwd=work,
                                   start_new_session=True, preexec_fn=pub_preexec)
        procs.append(pub)
        wait_for(ready, [(pub, pub_log), (sub, sub_log)], f"{tag}: first message on {topic}")
        yield Running(pub, sub, samples, pub_log, sub_log)
        stop(sub)
        if not samples.exists():
            raise RuntimeError(f"{tag}: subscriber wrote no samples: {tail(sub_log)}")
    finally:
        for p in reversed(procs):
            stop(p)


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

    :raises RuntimeError: as :func:`publisher_and_subscriber`, the publisher exited in the
        window, or the window held fewer than 3 messages
    """
    import numpy as np

    if spans is not None and span_env:
        env = {**env, SPAN_ENV: str(spans)}

    with publisher_and_subscriber(tag, cmd, topic, env, work) as run:
        time.sleep(WARMUP_S)
        kids = descendants(run.pub.pid)
        cpu0, kid0, w0, m0 = (cpu_seconds(run.pub.pid), cpu_of(kids), time.time_ns(),
                              time.monotonic())
        time.sleep(MEASURE_S)
        cpu1, kid1, w1, m1 = (cpu_seconds(run.pub.pid), cpu_of(kids), time.time_ns(),
                              time.monotonic())
        if run.pub.poll() is not None:
            raise RuntimeError(f"{tag}: publisher exited {run.pub.returncode}: "
                               f"{tail(run.pub_log)}")

    data = np.loadtxt(run.samples, dtype=np.int64, ndmin=2)
    recv, stamp = data[:, 0], data[:, 1]
    sel = (recv >= w0) & (recv < w1)
    recv, stamp = recv[sel], stamp[sel]
    window = (w1 - w0) / 1e9
    if len(recv) < 3:
        raise RuntimeError(f"{tag}: only {len(recv)} messages in the {window:.1f} s window")
    period_us = 1e6 / rate
    jitter = np.abs(np.diff(recv) / 1e3 - period_us)
    latency = (recv - stamp) / 1e3
    log = tail(run.pub_log, 200_000)
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
