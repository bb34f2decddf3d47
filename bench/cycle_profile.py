"""Where one cycle's time goes in the node, per step, from its own thread (in-process timing).

``python bench/cycle_profile.py [joints] [seconds] [--cprofile]``: one ``SsiBridgeNode`` in
this process (simulated station as its child process, the default), ``joints`` encoders on
slots 1..N at the case rate of ``bench_node.py`` (1 kHz, or the highest rate the wire allows
for N slots). Each step of publishing a cycle is wrapped in a timer on the node instance:

* ``decide``: the cycle core (``core/cycle.Cycle.run``) for every joint, of which
  ``verdict`` (the frame log's decisions, ``settled`` included, wherever it is asked) and
  ``joint`` (count, scale, velocity, frame checks, health) are the parts; ``settle``: the
  health of the SYNC before where it is judged after publishing (``Joint.settle``);
* ``build``: the JointState message; ``publish``: ``publish_safe`` of joint_states;
* ``levels``: the diagnostics' change test (``_publish_on_change``);
* ``cycle``: deciding the cycle and publishing its joint_states (``CyclePublisher._publish``,
  on the receive thread for a cycle that completes); ``finish``: the rest of the cycle on the
  cycle thread (``CyclePublisher._finish``: health of the SYNC before where it is judged
  there, events, ``~/status`` for a listener, recording, ``levels``);
* ``sync``: sending the SYNC (``client.sync``, the cycle thread), ``sync_cpu`` the CPU time
  of its thread meanwhile (the simulated wire sleeps until the frame's end); ``frame``: one received
  frame through the master's listener (counting, dispatch, slot table, frame log; the
  frame completing a cycle includes its publishing): per frame, not per cycle; ``frame_cpu``
  its thread's CPU time, ``recv_cpu`` the CPU time of the bus's ``recv`` that returned it
  (the receive thread's wait for the datagram included: python-can's Notifier calls it with
  a timeout). ``--frames`` prints the top functions (own time) of the frames' handling,
  ``--sync`` those (cumulative) of sending the SYNC.

Prints median / p99 (us) of each per cycle after a 2 s warm-up, then Python's garbage
collections in the window (per generation, and the threads they ran on) and the cycle
thread's cycles run and slots missed. ``--cprofile`` prints the
top functions (cumulative) of the cycle's thread instead; ``--plain`` wraps nothing (for a
sampling profiler of the whole process: ``python -X perf`` under ``perf record``); ``--span``,
``--span-frames``, ``--mt``: ``bench/cycle_span.py``. No subscriber: publish() serializes
and hands to DDS, nothing is sent. Numbers go to docs/node.md, "Performance".
"""

from __future__ import annotations

import contextlib
import cProfile
import io
import os
import pstats
import sys
import threading
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, os.path.dirname(__file__))
from bench_node import case_rate  # noqa: E402
from cycle_span import (note_threads, print_frames, print_spans, spin_callbacks,  # noqa: E402
                        thread_switches, watch_cycle_thread, watch_frames, watch_gc)

STEPS = ("sync", "sync_cpu", "recv_cpu", "frame", "frame_cpu", "cycle", "decide", "verdict", "joint", "settle", "build",
         "publish", "finish", "levels")


def _timed(into: dict[str, list[int]], step: str, fn: Callable[..., Any],
           acc: dict[str, int] | None = None) -> Callable[..., Any]:
    """``fn`` timed into ``into[step]`` (per call), or summed into ``acc[step]``."""
    clock = time.perf_counter_ns

    def wrapped(*args: Any, **kwargs: Any) -> Any:
        t0 = clock()
        try:
            return fn(*args, **kwargs)
        finally:
            dt = clock() - t0
            if acc is not None:
                acc[step] += dt
            else:
                into[step].append(dt)
    return wrapped


def _sample(seconds: float, interval: float = 0.0005, top: int = 45) -> list[str]:
    """Sample every other thread's Python stack each ``interval`` s for ``seconds``: share of
    the samples each function is on the stack (inclusive) and on top (self), per thread."""
    me = threading.get_ident()
    names = {t.ident: t.name for t in threading.enumerate()}
    inclusive: dict[str, int] = defaultdict(int)
    own: dict[str, int] = defaultdict(int)
    per_thread: dict[str, int] = defaultdict(int)
    n = 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for ident, frame in sys._current_frames().items():
            if ident == me:
                continue
            code = frame.f_code
            if code.co_name in ("select", "wait", "_wait_for_tstate_lock", "sleep"):
                continue  # blocked, not running
            thread = names.get(ident, str(ident))
            per_thread[thread] += 1
            n += 1
            seen = set()
            f: Any = frame
            top_done = False
            while f is not None:
                key = f"{thread[:10]:10s} {f.f_code.co_qualname} ({f.f_code.co_filename.rsplit('/', 1)[-1]})"
                if not top_done:
                    own[key] += 1
                    top_done = True
                if key not in seen:
                    inclusive[key] += 1
                    seen.add(key)
                f = f.f_back
        time.sleep(interval)
    out = [f"{n} samples: " + ", ".join(f"{k} {v}" for k, v in per_thread.items())]
    for key, c in sorted(inclusive.items(), key=lambda kv: -kv[1])[:top]:
        out.append(f"{100 * c / max(n, 1):5.1f}% {100 * own[key] / max(n, 1):5.1f}%  {key}")
    return out


def thread_cpu() -> dict[str, int]:
    """CPU ns each thread of this process has run (``/proc/self/task/*/schedstat``), by name
    (threads of the same name summed; a Python thread without a kernel name of its own by its
    Python name)."""
    out: dict[str, int] = defaultdict(int)
    named = {t.native_id: t.name for t in threading.enumerate()}
    for task in Path("/proc/self/task").iterdir():
        try:
            name = (task / "comm").read_text().strip()
            if name == "python":  # a Python thread that left its kernel name alone
                name = named.get(int(task.name), name)
            out[name] += int((task / "schedstat").read_text().split()[0])
        except OSError:
            continue  # the thread ended
    return out


def main(argv: list[str]) -> int:
    from rclpy.parameter import Parameter


    args = [a for a in argv if not a.startswith("--")]
    joints = int(args[0]) if args else 8
    seconds = float(args[1]) if len(args) > 1 else 5.0
    rate = case_rate(joints)
    names = [f"j{i + 1}" for i in range(joints)]
    params = [Parameter("joints", value=names), Parameter("publish_rate", value=rate),
              Parameter("bus.bitrate", value=1_000_000),
              Parameter("bus.channel", value=f"cycle_profile_{os.getpid()}"),
              Parameter("storage_path", value=f"/tmp/cycle_profile_{joints}/retentive.json")]
    params += [Parameter(f"{n}.slot", value=i + 1) for i, n in enumerate(names)]
    station = contextlib.nullcontext()
    if "--real" in argv:  # the node as a real deployment runs it, its station apart
        import yaml

        from real_station import real_params, station_process

        extra = real_params(f"cycle_profile_{os.getpid()}")
        params += [Parameter(k, value=v) for k, v in extra.items()]
        pfile = Path(f"/tmp/cycle_profile_{os.getpid()}.yaml")
        pfile.write_text(yaml.safe_dump({"/**": {"ros__parameters": {
            "joints": names, "bus.bitrate": 1_000_000,
            **{f"{n}.slot": i + 1 for i, n in enumerate(names)}}}}))
        station = station_process(Path(__file__).resolve().parent.parent, pfile,
                                  extra["bus.channel"], dict(os.environ),
                                  pfile.with_suffix(".log"))
    with station:
        return _profile(argv, joints, seconds, rate, params)


def _profile(argv: list[str], joints: int, seconds: float, rate: float, params: list) -> int:
    """Run and time the node on ``params`` (see the module docstring)."""
    import numpy as np
    import rclpy

    from ssi_bridge.ros.node import SsiBridgeNode

    span_log = Path(f"/tmp/cycle_profile_span_{os.getpid()}.bin")
    if "--span" in argv:  # the node's span probe (ros/span_probe.py), read at its start
        span_log.unlink(missing_ok=True)
        os.environ["SSI_BRIDGE_SPAN_LOG"] = str(span_log)
    rclpy.init(args=None)
    node = SsiBridgeNode(parameter_overrides=params)
    for a in argv:  # --switch=S: Python's switch interval (s) for this run, set after the
        if a.startswith("--switch="):  # node set its own at start (ros/node_start.py)
            sys.setswitchinterval(float(a.split("=", 1)[1]))
    blocks: list[tuple[int, int]] = []
    busy: list[tuple[str, int, int, int]] = []
    if "--span" in argv:  # when the cycle thread blocks, and the periodic diagnostics run
        watch_cycle_thread(node, blocks, busy)
    frames: list[tuple[int, int, int, int, int, int, int]] = []
    if "--span-frames" in argv:  # each frame's receive and handling, beside the spans
        watch_frames(node, frames)
        watch_gc(busy)
    per_cycle: dict[str, list[int]] = defaultdict(list)
    acc: dict[str, int] = defaultdict(int)
    measuring = threading.Event()
    profile = cProfile.Profile() if "--cprofile" in argv else None
    publisher = node.cycle_publisher
    whole = publisher._publish

    def cycle(*a: Any) -> Any:
        if not measuring.is_set():
            return whole(*a)
        acc.clear()
        if profile is not None:
            profile.enable()
        t0 = time.perf_counter_ns()
        try:
            return whole(*a)
        finally:
            per_cycle["cycle"].append(time.perf_counter_ns() - t0)
            if profile is not None:
                profile.disable()
            for k in ("verdict", "joint", "settle"):
                per_cycle[k].append(acc[k])

    if "--sample" in argv:  # nothing wrapped: where every thread of the node spends time
        threading.Thread(target=spin_callbacks(argv), args=(node,), daemon=True).start()
        time.sleep(2.0)
        counts = _sample(seconds)
        node.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
        for line in counts:
            print(line)
        return 0
    diag_profile = cProfile.Profile() if "--diag" in argv else None
    if diag_profile is not None:  # the diagnostics' publish, wherever it runs (cProfile)
        diag_publish = node.diagnostics.publish

        def profiled_publish() -> None:
            diag_profile.enable()
            try:
                diag_publish()
            finally:
                diag_profile.disable()

        node.diagnostics.publish = profiled_publish  # type: ignore[method-assign]
    if "--plain" in argv:  # nothing wrapped: each thread's CPU, for perf or a sampler
        threading.Thread(target=spin_callbacks(argv), args=(node,), daemon=True).start()
        time.sleep(2.0)
        cpu0, c0, w0 = thread_cpu(), node.cycle.cycles, time.time_ns()
        sw0 = thread_switches()
        note_threads()
        print(f"measuring pid {os.getpid()} for {seconds:g} s", flush=True)
        time.sleep(seconds)
        cpu1, cycles = thread_cpu(), node.cycle.cycles - c0
        sw1 = thread_switches()
        node.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
        print(f"{cycles} cycles; CPU per thread, s/s (us per cycle): " + ", ".join(
            f"{name} {(cpu1[name] - cpu0.get(name, 0)) / 1e9 / seconds:.3f} "
            f"({(cpu1[name] - cpu0.get(name, 0)) / 1e3 / max(cycles, 1):.0f})"
            for name in sorted(cpu1, key=lambda n: cpu0.get(n, 0) - cpu1[n])[:6]))
        print("wake-ups per s: " + ", ".join(
            f"{name} {(sw1[name] - sw0.get(name, 0)) / seconds:.0f}"
            for name in sorted(sw1, key=lambda n: sw0.get(n, 0) - sw1[n])[:10]))
        if "--span" in argv:
            recs = print_spans(span_log, blocks, w0, busy)
            if frames:
                print_frames(recs, frames, blocks, busy)
        if diag_profile is not None:
            out = io.StringIO()
            pstats.Stats(diag_profile, stream=out).sort_stats("cumulative").print_stats(30)
            print(out.getvalue())
        return 0
    publisher._publish = cycle  # type: ignore[method-assign]
    publisher._finish = _timed(per_cycle, "finish", publisher._finish)  # type: ignore
    sync = node.client.sync

    sync_profile = cProfile.Profile() if "--sync" in argv else None

    def timed_sync() -> float:
        if not measuring.is_set():
            return sync()
        if sync_profile is not None:
            sync_profile.enable()
        t0, c0 = time.perf_counter_ns(), time.thread_time_ns()
        try:
            return sync()
        finally:
            per_cycle["sync"].append(time.perf_counter_ns() - t0)
            per_cycle["sync_cpu"].append(time.thread_time_ns() - c0)
            if sync_profile is not None:
                sync_profile.disable()

    node.client.sync = timed_sync  # type: ignore[method-assign]
    listener = node.master._listener
    on_frame = listener.on_message_received

    frame_profile = cProfile.Profile() if "--frames" in argv else None

    def timed_frame(msg: Any) -> None:
        if not measuring.is_set():
            return on_frame(msg)
        if frame_profile is not None:
            frame_profile.enable()
        t0, c0 = time.perf_counter_ns(), time.thread_time_ns()
        try:
            return on_frame(msg)
        finally:
            per_cycle["frame"].append(time.perf_counter_ns() - t0)
            per_cycle["frame_cpu"].append(time.thread_time_ns() - c0)
            if frame_profile is not None:
                frame_profile.disable()

    listener.on_message_received = timed_frame  # type: ignore[method-assign]
    bus = node.master.network.bus
    recv = bus.recv

    def timed_recv(timeout: float | None = None) -> Any:
        c0 = time.thread_time_ns()
        msg = recv(timeout)
        if msg is not None and measuring.is_set():
            per_cycle["recv_cpu"].append(time.thread_time_ns() - c0)
        return msg

    bus.recv = timed_recv  # type: ignore[method-assign]
    node.cycle_core.run = _timed(per_cycle, "decide", node.cycle_core.run)  # type: ignore
    states = publisher._joint_states  # the kept joint_states message and its filling
    states.fill = _timed(per_cycle, "build", states.fill)  # type: ignore[method-assign]
    node.publish_safe = _timed(per_cycle, "publish", node.publish_safe)  # type: ignore
    node._publish_on_change = _timed(per_cycle, "levels", node._publish_on_change)  # type: ignore
    for log in set(node.frame_logs.values()):
        log.verdict = _timed(per_cycle, "verdict", log.verdict, acc)  # type: ignore
    for j in node.joints.values():
        for method in ("count", "update", "output", "leave_out", "set_aside"):
            if hasattr(j, method):
                setattr(j, method, _timed(per_cycle, "joint", getattr(j, method), acc))
        if hasattr(j, "settle"):  # the health of the SYNC before, after publishing
            j.settle = _timed(per_cycle, "settle", j.settle, acc)  # type: ignore
    spinner = threading.Thread(target=spin_callbacks(argv), args=(node,), daemon=True)
    spinner.start()
    import gc

    gc_runs: dict[int, list[int]] = defaultdict(list)
    gc_start = [0]
    gc_threads: dict[str, int] = defaultdict(int)

    def on_gc(phase: str, info: dict) -> None:
        if not measuring.is_set():
            return
        if phase == "start":
            gc_start[0] = time.perf_counter_ns()
        else:
            gc_runs[info["generation"]].append(time.perf_counter_ns() - gc_start[0])
            gc_threads[threading.current_thread().name] += 1

    gc.callbacks.append(on_gc)
    try:
        time.sleep(2.0)
        c0, m0, i0 = node.cycle.cycles, node.cycle.missed, node.cycle_core.incomplete_cycles
        cpu0 = thread_cpu()
        measuring.set()
        time.sleep(seconds)
        measuring.clear()
        cpu1 = thread_cpu()
        print("CPU per thread, s/s (schedstat): " + ", ".join(
            f"{name} {(cpu1[name] - cpu0.get(name, 0)) / 1e9 / seconds:.3f}"
            for name in sorted(cpu1, key=lambda n: cpu0.get(n, 0) - cpu1[n])))
        for gen in sorted(gc_runs):
            runs = np.array(gc_runs[gen]) / 1e3
            print(f"gc generation {gen}: {len(runs)} collections, median {np.median(runs):.0f} "
                  f"us, max {runs.max():.0f} us")
        print(f"gc collections by thread: {dict(gc_threads)}")
        print(f"cycle thread: {node.cycle.cycles - c0} cycles run, {node.cycle.missed - m0} "
              f"slots missed, {node.cycle_core.incomplete_cycles - i0} cycles with a joint "
              f"left out, in {seconds:g} s")
    finally:
        node.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    if sync_profile is not None:
        out = io.StringIO()
        pstats.Stats(sync_profile, stream=out).sort_stats("cumulative").print_stats(30)
        print(out.getvalue())
    if frame_profile is not None:
        out = io.StringIO()
        pstats.Stats(frame_profile, stream=out).sort_stats("tottime").print_stats(30)
        print(out.getvalue())
    if profile is not None:
        out = io.StringIO()
        pstats.Stats(profile, stream=out).sort_stats("cumulative").print_stats(35)
        print(out.getvalue())
        return 0
    print(f"{joints} joint(s) at {rate:g} Hz, {len(per_cycle['cycle'])} cycles, us median / p99:")
    for step in STEPS:
        v = np.array(per_cycle.get(step, [0])) / 1e3
        print(f"  {step:8s} {np.percentile(v, 50):8.1f} / {np.percentile(v, 99):8.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
