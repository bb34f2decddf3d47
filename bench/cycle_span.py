"""``bench/cycle_profile.py --span``: the driver's span beside what overlapped its slowest 1 %.

The span (ros/span_probe.py: the completing frame's receive timestamp to ``publish()``
returned) is lined up with when the cycle thread began each SYNC and its wait (was it still
running, holding Python's lock, when the frame came?) and with when the periodic diagnostics
ran (``_refresh_cams``, ``publish`` on the executor thread).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any


def watch_cycle_thread(node: Any, blocks: list[tuple[int, int]],
                       busy: list[tuple[str, int, int, int]]) -> None:
    """Wrap ``node``'s SYNC and wait so that each cycle's (SYNC began, wait began) in ns
    goes to ``blocks``, and the periodic diagnostics' parts so that each run goes to
    ``busy`` (:func:`interval`)."""
    master = node.master
    wait_claim = master.wait_claim

    client_sync = node.client.sync
    started = [0]

    def stamped_sync() -> float:
        started[0] = time.time_ns()
        return client_sync()

    def stamped_wait(*a: Any) -> bool:
        blocks.append((started[0], time.time_ns()))
        return wait_claim(*a)

    master.wait_claim = stamped_wait  # type: ignore[method-assign]
    node.client.sync = stamped_sync  # type: ignore[method-assign]
    diag = node.diagnostics
    for method in ("_refresh_cams", "publish"):  # the periodic diagnostics' parts
        setattr(diag, method, interval(busy, method, getattr(diag, method)))


def interval(into: list[tuple[str, int, int, int]], what: str,
             fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn``, each call's (what, start, end, thread CPU) in ns (``time.time_ns``,
    ``time.thread_time_ns``) appended to ``into``."""
    def wrapped(*args: Any, **kwargs: Any) -> Any:
        t0, c0 = time.time_ns(), time.thread_time_ns()
        try:
            return fn(*args, **kwargs)
        finally:
            into.append((what, t0, time.time_ns(), time.thread_time_ns() - c0))
    return wrapped


def print_spans(path: Path, blocks: list[tuple[int, int]], since_ns: int,
                 busy: list[tuple[str, int, int, int]]) -> None:
    """``--span``: the driver's span (ros/span_probe.py) after ``since_ns``, and how often the
    cycle thread had not yet blocked for the cycle (``blocks``: when it began its SYNC and
    its wait, ns)
    when the cycle's completing frame was received: it held the GIL against the receive
    thread then."""
    import bisect

    import numpy as np

    from ssi_bridge.ros.span_probe import read_spans

    recs = [r for r in read_spans(str(path)) if r[0] >= since_ns]
    path.unlink(missing_ok=True)
    if not recs:
        print("span: no records")
        return
    span = np.array([p - r for r, p, _ in recs]) / 1e3
    starts = [s for s, _ in blocks]
    late = []  # the cycle thread blocked after the frame arrived (it ran meanwhile)
    for rx, _, _ in recs:
        i = bisect.bisect_right(starts, rx) - 1  # the cycle whose SYNC went out last
        late.append(i >= 0 and blocks[i][1] > rx)
    mask = np.array(late)
    q = lambda a: "/".join(f"{np.percentile(a, x):.0f}" for x in (50, 90, 99)) if len(a) else "-"
    print(f"span us p50/p90/p99 {q(span)} ({len(span)} cycles); the cycle thread not yet "
          f"blocked at the frame: {mask.mean() * 100:.1f} % of cycles, span {q(span[mask])}; "
          f"else {q(span[~mask])}; of the slowest 1 %: "
          f"{mask[span >= np.percentile(span, 99)].mean() * 100:.0f} %")
    slow = span >= np.percentile(span, 99)
    for what in sorted({w for w, _, _, _ in busy}):
        runs = [(t0, t1) for w, t0, t1, _ in busy if w == what and t1 >= since_ns]
        cpu = np.array([c for w, _, t1, c in busy if w == what and t1 >= since_ns]) / 1e3
        hit = np.array([any(t0 <= p and t1 >= r for t0, t1 in runs) for r, p, _ in recs])
        took = np.array([t1 - t0 for t0, t1 in runs]) / 1e3
        print(f"{what}: {len(runs)} runs, median {np.median(took) if len(took) else 0:.0f} us "
              f"(CPU {np.median(cpu) if len(cpu) else 0:.0f} us); "
              f"overlapping {hit.mean() * 100:.2f} % of spans, {hit[slow].mean() * 100:.0f} % "
              f"of the slowest 1 %; span of those {q(span[hit])}")
