"""``bench/cycle_profile.py --span``: the driver's span beside what overlapped its slowest 1 %.

The span (ros/span_probe.py: the completing frame's receive timestamp to ``publish()``
returned) is lined up with when the cycle thread began each SYNC and its wait (was it still
running, holding Python's lock, when the frame came?) and with when the periodic diagnostics
ran (``_refresh_cams``, ``publish`` on the executor thread). ``--span-frames`` takes each span
apart by the frames around it (:func:`print_frames`: the completing frame's wake-up, whether
the receive thread was still busy when it came, its handling, which thread published) and
notes the garbage collections; with ``CYCLE_SPAN_DUMP=<file>`` every span's times go to that
file as JSON (monotonic offset and thread names included), to line up with ``perf sched
record -k mono``. ``--mt`` runs the node's callbacks as the ``ssi_bridge_node`` program does
(:func:`spin_callbacks`); ``--plain`` prints each thread's wake-ups per second too
(:func:`thread_switches`).
"""

from __future__ import annotations

import os
import threading
import time
from collections import defaultdict
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


def watch_frames(node: Any, frames: list[tuple[int, int, int, int, int, int, int]]) -> None:
    """Wrap the receive thread's ``recv`` and the master's listener so that each received
    frame's (COB-ID, kernel receive ns, recv entered, recv returned, handling began, handling
    ended, handling's thread CPU ns) goes to ``frames`` (wall ns, ``time.time_ns``)."""
    bus = node.master.network.bus
    recv = bus.recv
    listener = node.master._listener
    on_frame = listener.on_message_received
    entered = [0, 0]

    def timed_recv(timeout: float | None = None) -> Any:
        t0 = time.time_ns()
        msg = recv(timeout)
        entered[0], entered[1] = t0, time.time_ns()
        return msg

    def timed_frame(msg: Any) -> None:
        t0, c0 = time.time_ns(), time.thread_time_ns()
        try:
            on_frame(msg)
        finally:
            frames.append((msg.arbitration_id, round(msg.timestamp * 1e9), entered[0],
                           entered[1], t0, time.time_ns(), time.thread_time_ns() - c0))

    bus.recv = timed_recv  # type: ignore[method-assign]
    listener.on_message_received = timed_frame  # type: ignore[method-assign]
    probe = node._span_probe
    if probe is not None:
        published = probe.published

        def noted(received_s: float, joints: int) -> None:
            published(received_s, joints)
            BY_CYCLE_THREAD[round(received_s * 1e9)] = \
                threading.current_thread().name == "ssi_cycle"

        probe.published = noted  # type: ignore[method-assign]


#: native thread id -> name of the node's threads, noted when the measuring began
THREAD_NAMES: dict[int, str] = {}


def note_threads() -> None:
    """Note the process's threads' names by native id (for ``CYCLE_SPAN_DUMP``)."""
    THREAD_NAMES.update({t.native_id: t.name for t in threading.enumerate()
                         if t.native_id is not None})


#: receive ns of a published cycle's newest frame -> whether the cycle thread published it
BY_CYCLE_THREAD: dict[int, bool] = {}


def watch_gc(busy: list[tuple[str, int, int, int]]) -> None:
    """Each garbage collection's (``gc<generation> <thread>``, start, end, 0) to ``busy``."""
    import gc

    began = [0]

    def on_gc(phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            began[0] = time.time_ns()
        else:
            busy.append((f"gc{info['generation']} {threading.current_thread().name}",
                         began[0], time.time_ns(), 0))

    gc.callbacks.append(on_gc)


def print_frames(recs: list[tuple[int, int, int]],
                 frames: list[tuple[int, int, int, int, int, int, int]],
                 blocks: list[tuple[int, int]] = [],
                 busy: list[tuple[str, int, int, int]] = []) -> None:
    """Each span taken apart by the frames around it: the completing frame's wake-up (kernel
    stamp to its ``recv`` returning), whether the receive thread was still busy with an
    earlier frame when it arrived (behind), its handling (decide, build, publish) wall and
    CPU, and frames other than the cycle's TPDOs (SDO answers) received in the cycle."""
    import bisect

    import numpy as np

    frames.sort(key=lambda f: f[4])
    starts = [f[4] for f in frames]
    rows = []
    windows: list[tuple[int, int, int]] = []
    trail: list[tuple[int, list[tuple[int, ...]], int]] = []
    for rx, pub, _ in recs:
        i = bisect.bisect_right(starts, pub) - 1  # the frame whose handling published
        while i >= 0 and frames[i][1] != rx:
            i -= 1
        if i < 0 or pub - frames[i][4] > 10_000_000:
            continue
        cob, ts, r0, r1, h0, h1, cpu = frames[i]
        behind = r0 > ts  # recv entered only after the frame was in the kernel
        late = sum(1 for f in frames[max(0, i - 14):i]  # earlier frames of the cycle done
                   if f[1] > rx - 1_900_000 and f[5] > f[1] + 100_000)  # > 100 us late
        others = sum(1 for f in frames[max(0, i - 14):i] if f[1] > rx - 1_900_000
                     and not (0x180 <= f[0] < 0x500))
        trail.append((pub - rx, [(f[0], (f[1] - rx) // 1000, (f[2] - rx) // 1000,
                                  (f[3] - rx) // 1000, (f[4] - rx) // 1000,
                                  (f[5] - rx) // 1000, f[6] // 1000)
                                 for f in frames[max(0, i - 6):i + 1]], rx))
        windows.append((rx, r1, pub))
        rows.append((pub - rx, r1 - ts, h0 - r1, pub - h0, cpu, behind, late, others,
                     max(0, r0 - ts), BY_CYCLE_THREAD.get(rx, False)))
    dump = os.environ.get("CYCLE_SPAN_DUMP")
    if dump:  # every span's (receive, its recv returned, published) ns, for perf sched
        import json

        Path(dump).write_text(json.dumps({"realtime_minus_monotonic":
                                          time.time_ns() - time.monotonic_ns(),
                                          "spans": windows,
                                          "threads": THREAD_NAMES}))
    if not rows:
        print("frames: none matched")
        return
    a = np.array(rows, dtype=float)
    a[:, :5] /= 1e3
    a[:, 8] /= 1e3
    slow = a[:, 0] >= np.percentile(a[:, 0], 99)
    rest = a[:, 0] < np.percentile(a[:, 0], 50)
    for label, m in (("slowest 1 %", slow), ("fastest half", rest), ("all", np.ones(len(a), bool))):
        b = a[m]
        med = lambda c: f"{np.median(b[:, c]):.0f}/{np.percentile(b[:, c], 90):.0f}"
        print(f"{label} ({len(b)}): span {med(0)}, wake (kernel->recv out) {med(1)}, "
              f"recv out->handling {med(2)}, handling {med(3)} (CPU {med(4)}), "
              f"rx busy at arrival {b[:, 5].mean() * 100:.0f} % (by {med(8)}), earlier frames "
              f"done >100 us late {b[:, 6].mean():.2f}, "
              f"non-TPDO frames in cycle {b[:, 7].mean():.2f}, "
              f"published by the cycle thread {b[:, 9].mean() * 100:.0f} %")
    show = int(os.environ.get("CYCLE_SPAN_SHOW", "8"))
    if slow.any():
        print("slowest: span wake r->h handl cpu busy late others behind_by by_cycle")
        for row in a[slow][np.argsort(-a[slow][:, 0])][:12]:
            print("  " + " ".join(f"{v:6.0f}" for v in row))
        print(f"the {show} slowest, frames before (cob, kernel, recv in, recv out, "
              "handling in, out, "
              "cpu; us from the completing frame's kernel stamp):")
        for span, fs, rx in sorted(trail, key=lambda t: -t[0])[:show]:
            print(f"  span {span / 1e3:.0f}: " + "  ".join(
                f"{c:03x}:{k}/{a}/{b}/{h}/{e}/{u}" for c, k, a, b, h, e, u in fs))
            near = [f"sync {(s0 - rx) // 1000} wait {(w0 - rx) // 1000}" for s0, w0 in blocks
                    if -3_000_000 < s0 - rx < 2_000_000]
            near += [f"{w} {(t0 - rx) // 1000}..{(t1 - rx) // 1000}" for w, t0, t1, _ in busy
                     if t1 > rx - 3_000_000 and t0 < rx + 2_000_000]
            print("     " + "; ".join(near))


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
                 busy: list[tuple[str, int, int, int]]) -> list[tuple[int, int, int]]:
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
        return recs
    span = np.array([p - r for r, p, _ in recs]) / 1e3
    starts = [s for s, _ in blocks]
    late = []  # the cycle thread blocked after the frame arrived (it ran meanwhile)
    for rx, _, _ in recs:
        i = bisect.bisect_right(starts, rx) - 1  # the cycle whose SYNC went out last
        late.append(i >= 0 and blocks[i][1] > rx)
    mask = np.array(late)
    q = lambda a: "/".join(f"{np.percentile(a, x):.0f}" for x in (50, 90, 99)) if len(a) else "-"
    print(f"span us p50/p90/p99 {q(span)} ({len(span)} cycles, {(span > 400).mean() * 100:.2f} "
          f"% above 400 us); the cycle thread not yet "
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
    return recs


def spin_callbacks(argv: list[str]) -> Callable[[Any], None]:
    """How the node's callbacks run: ``rclpy.spin`` (one thread), or with ``--mt`` as the
    ``ssi_bridge_node`` program runs them (``MultiThreadedExecutor(4)``, ``spin_once``
    until the context ends)."""
    import rclpy

    if "--mt" not in argv:
        return rclpy.spin

    def spin(node: Any) -> None:
        from rclpy.executors import MultiThreadedExecutor

        executor = MultiThreadedExecutor(num_threads=4)
        executor.add_node(node)
        try:
            while rclpy.ok():
                executor.spin_once(timeout_sec=0.5)
        except Exception:  # noqa: BLE001 - the context ended under a callback
            pass
    return spin


def thread_switches() -> dict[str, int]:
    """Voluntary context switches (wake-ups) each thread of this process has had, by name (as
    :func:`thread_cpu`)."""
    out: dict[str, int] = defaultdict(int)
    named = {t.native_id: t.name for t in threading.enumerate()}
    for task in Path("/proc/self/task").iterdir():
        try:
            name = (task / "comm").read_text().strip()
            if name == "python":
                name = named.get(int(task.name), name)
            for line in (task / "status").read_text().splitlines():
                if line.startswith("voluntary_ctxt_switches"):
                    out[name] += int(line.split()[1])
        except OSError:
            continue
    return out
