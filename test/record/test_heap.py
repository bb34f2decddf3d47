"""record/heap.py: free C-heap pages held under a live block go back to the OS after a split.

The situation the soak benchmark measured (RSS of a recording node grew by the free memory
glibc kept in its arenas): freed blocks below a block still in use cannot be returned by
glibc's automatic trim, which only shrinks the top of a heap. Run in a child process so the
test process's own heap does not blur the figures.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys

import pytest

CHILD = r"""
import ctypes, ctypes.util, json
from ssi_bridge.record.heap import release_free_memory
libc = ctypes.CDLL(ctypes.util.find_library("c"))
libc.malloc.restype = ctypes.c_void_p
libc.free.argtypes = [ctypes.c_void_p]
def rss_mb():
    with open("/proc/self/status") as f:
        return next(int(l.split()[1]) for l in f if l.startswith("VmRSS:")) / 1024
blocks = [libc.malloc(64 * 1024) for _ in range(800)]       # 50 MB below the mmap threshold
for b in blocks:
    ctypes.memset(b, 1, 64 * 1024)
pin = libc.malloc(64)                                       # a live block above them
for b in blocks:
    libc.free(b)
before = rss_mb()
released = release_free_memory()
print(json.dumps({"before": before, "after": rss_mb(), "released": released}))
"""


def run_child(**env: str) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD], env={**os.environ, **env},
                         capture_output=True, text=True, timeout=60, check=True)
    return json.loads(out.stdout)


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="malloc_trim is glibc's")
def test_free_pages_below_a_live_block_are_returned() -> None:
    figures = run_child()
    assert figures["released"] is True
    assert figures["before"] - figures["after"] > 40, figures


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="malloc_trim is glibc's")
def test_switched_off_keeps_them() -> None:
    figures = run_child(SSI_BRIDGE_MALLOC_TRIM="0")
    assert figures["released"] is False
    assert figures["before"] - figures["after"] < 5, figures


THRESHOLD_CHILD = r"""
import ctypes, json, sys
from ssi_bridge.record import heap
from ssi_bridge.tools.memprobe import malloc_figures
if sys.argv[1] == "fixed":
    heap.fix_mmap_threshold()
libc = heap.libc()
libc.malloc.restype = ctypes.c_void_p
libc.malloc.argtypes = [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]
libc.free(libc.malloc(4 << 20))          # a freed mmapped block: glibc would raise its threshold
before = malloc_figures(libc)["malloc_mmap_mb"]
block = libc.malloc(512 * 1024)          # the size of a chunk's buffer or compressed bytes
after = malloc_figures(libc)["malloc_mmap_mb"]
libc.free(block)
print(json.dumps({"mmapped_mb": after - before}))
"""


def mmapped_after_a_free(mode: str) -> float:
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_MMAP_THRESHOLD_"}
    out = subprocess.run([sys.executable, "-c", THRESHOLD_CHILD, mode], env=env,
                         capture_output=True, text=True, timeout=60, check=True)
    return json.loads(out.stdout)["mmapped_mb"]


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallopt is glibc's")
def test_fixed_mmap_threshold_keeps_large_blocks_out_of_the_heap() -> None:
    """A 512 kB block gets its own mapping even after a larger mapped block was freed (glibc
    alone would have raised its threshold and put it in the heap, docs/node.md "Memory")."""
    assert mmapped_after_a_free("fixed") >= 0.5
    assert mmapped_after_a_free("default") == 0.0
