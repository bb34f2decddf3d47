"""Memory probe for long runs: ``SSI_BRIDGE_MEMPROBE=<file>`` makes the node log its memory.

A daemon thread appends one JSON line every ``SSI_BRIDGE_MEMPROBE_PERIOD`` seconds (30): RSS
and its anonymous part (``/proc/self/smaps_rollup``), glibc's malloc figures (``mallinfo2``:
bytes in use, free bytes kept, mmapped blocks; the number of arenas from ``malloc_info``),
the thread count, and with ``SSI_BRIDGE_MEMPROBE_TRACE=1`` the Python heap (tracemalloc) and
its ten largest growths since the previous line; with ``SSI_BRIDGE_MEMPROBE_TRIM=1`` it calls
``malloc_trim(0)`` after each line (how much of the RSS is free memory malloc keeps). It
separates Python-heap growth from C-level growth and, within C, memory in use from freed
memory malloc keeps (fragmentation): the questions behind the soak benchmark's RSS slope.
Off unless the variable is set.
"""

from __future__ import annotations

import ctypes
import json
import os
import re
import threading
import time
import tracemalloc
from typing import Any

from ssi_bridge.record.heap import libc as heap_libc

ENV_FILE = "SSI_BRIDGE_MEMPROBE"
ENV_PERIOD = "SSI_BRIDGE_MEMPROBE_PERIOD"
ENV_TRACE = "SSI_BRIDGE_MEMPROBE_TRACE"
ENV_TRIM = "SSI_BRIDGE_MEMPROBE_TRIM"


class _Mallinfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
        "fordblks", "keepcost")]


def malloc_figures(libc: ctypes.CDLL) -> dict[str, Any]:
    """glibc's heap: in use, free but kept, mmapped (MB) and the number of arenas.

    :param libc: glibc, loaded (``mallinfo2``)
    """
    libc.mallinfo2.restype = _Mallinfo2
    m = libc.mallinfo2()
    out: dict[str, Any] = {"malloc_in_use_mb": m.uordblks / 2**20,
                           "malloc_free_mb": m.fordblks / 2**20,
                           "malloc_mmap_mb": m.hblkhd / 2**20,
                           "malloc_heap_mb": m.arena / 2**20}
    size = ctypes.c_size_t(0)
    buf = ctypes.c_char_p(None)
    libc.open_memstream.restype = ctypes.c_void_p
    stream = libc.open_memstream(ctypes.byref(buf), ctypes.byref(size))
    if stream:
        libc.malloc_info(0, ctypes.c_void_p(stream))
        libc.fclose(ctypes.c_void_p(stream))
        text = ctypes.string_at(buf, size.value).decode(errors="replace")
        libc.free(buf)
        out["arenas"] = len(re.findall(r"<heap nr=", text))
    return out


def rollup() -> dict[str, float]:
    """RSS, anonymous and file-backed resident memory of this process (MB)."""
    out: dict[str, float] = {}
    with open("/proc/self/smaps_rollup") as f:
        for line in f:
            key, _, rest = line.partition(":")
            if key in ("Rss", "Anonymous", "Private_Dirty", "Shared_Clean", "Private_Clean"):
                out[key.lower() + "_mb"] = int(rest.split()[0]) / 1024.0
    return out


#: glibc's thread arenas are reserved as 64 MB heaps aligned to their size (HEAP_MAX_SIZE)
ARENA_ALIGN = 64 * 2**20


def regions() -> dict[str, float]:
    """Resident anonymous memory by kind of mapping (MB), from ``/proc/self/smaps``: the
    main malloc heap (``[heap]``), thread arenas (64 MB-aligned), 1 MB maps (pymalloc's
    arenas), 8 MB maps (thread stacks), other anonymous maps and file-backed maps."""
    out = {"heap": 0.0, "arenas": 0.0, "pymalloc": 0.0, "stacks": 0.0, "anon_other": 0.0,
           "files": 0.0}
    kind = "files"
    with open("/proc/self/smaps") as f:
        for line in f:
            first = line.split(None, 6)
            if "-" in first[0] and len(first) >= 5 and ":" not in first[0]:
                start, end = (int(x, 16) for x in first[0].split("-"))
                path = first[5].strip() if len(first) > 5 else ""
                size = end - start
                if path == "[heap]":
                    kind = "heap"
                elif path.startswith("[stack"):
                    kind = "stacks"
                elif path:
                    kind = "files"
                elif start % ARENA_ALIGN == 0 and size < ARENA_ALIGN:
                    kind = "arenas"
                elif size == 2**20:
                    kind = "pymalloc"
                elif size == 8 * 2**20:
                    kind = "stacks"
                else:
                    kind = "anon_other"
            elif first[0] == "Rss:":
                out[kind] += int(first[1]) / 1024.0
    return {f"rss_{k}_mb": v for k, v in out.items()}


def _loop(path: str, period: float, trace: bool, trim: bool) -> None:
    libc = heap_libc()
    t0 = time.monotonic()
    prev = tracemalloc.take_snapshot() if trace else None
    while True:
        time.sleep(period)
        rec: dict[str, Any] = {"t": round(time.monotonic() - t0, 1), **rollup(), **regions(),
                               "threads": len(os.listdir("/proc/self/task"))}
        if libc is not None:
            rec.update(malloc_figures(libc))
            if trim:
                libc.malloc_trim(0)
        if trace and prev is not None:
            snap = tracemalloc.take_snapshot()
            rec["py_traced_mb"] = tracemalloc.get_traced_memory()[0] / 2**20
            rec["py_top"] = [f"{s.size_diff / 1024:+.1f} kB {s.count_diff:+d} "
                             f"{s.traceback[0].filename}:{s.traceback[0].lineno}"
                             for s in snap.compare_to(prev, "lineno")[:10]]
            prev = snap
        with open(path, "a") as f:
            f.write(json.dumps({k: round(v, 3) if isinstance(v, float) else v
                                for k, v in rec.items()}) + "\n")


def start_from_env() -> None:
    """Start the probe thread if ``SSI_BRIDGE_MEMPROBE`` names a file."""
    path = os.environ.get(ENV_FILE)
    if not path:
        return
    trace = os.environ.get(ENV_TRACE, "") not in ("", "0")
    if trace:
        tracemalloc.start(1)
    period = float(os.environ.get(ENV_PERIOD, "30"))
    trim = os.environ.get(ENV_TRIM, "") not in ("", "0")
    threading.Thread(target=_loop, args=(path, period, trace, trim), name="memprobe",
                     daemon=True).start()
