"""tools/memprobe.py: with SSI_BRIDGE_MEMPROBE set, a process logs its memory by kind, so
Python-heap growth, malloc bytes in use and free bytes malloc keeps can be told apart."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest

CHILD = r"""
import os, time
from ssi_bridge.tools.memprobe import start_from_env
start_from_env()
keep = [bytes(1000) for _ in range(20000)]   # ~20 MB of Python objects while it samples
deadline = time.monotonic() + 30
while time.monotonic() < deadline:            # two lines written after the objects exist
    time.sleep(0.2)
    path = os.environ["SSI_BRIDGE_MEMPROBE"]
    if os.path.exists(path) and sum(1 for _ in open(path)) >= 3:
        break
"""


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallinfo2 is glibc's")
def test_probe_lines_separate_python_heap_malloc_and_regions(tmp_path: Path) -> None:
    out = tmp_path / "mem.jsonl"
    subprocess.run([sys.executable, "-c", CHILD], check=True, timeout=60,
                   env={**os.environ, "SSI_BRIDGE_MEMPROBE": str(out),
                        "SSI_BRIDGE_MEMPROBE_PERIOD": "0.2", "SSI_BRIDGE_MEMPROBE_TRACE": "1"})
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(rows) >= 2
    last = rows[-1]
    for key in ("rss_mb", "anonymous_mb", "malloc_in_use_mb", "malloc_free_mb", "arenas",
                "rss_heap_mb", "rss_arenas_mb", "rss_pymalloc_mb", "threads"):
        assert key in last, key
    assert last["py_traced_mb"] > 18          # the 20 MB the child holds, seen by tracemalloc
    assert last["malloc_in_use_mb"] > 18      # 1000-byte objects come from malloc
    assert last["arenas"] >= 1


def test_off_without_the_variable(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("SSI_BRIDGE_MEMPROBE")}
    out = subprocess.run([sys.executable, "-c", "import threading; from ssi_bridge.tools."
                          "memprobe import start_from_env; start_from_env(); "
                          "print(threading.active_count())"],
                         env=env, capture_output=True, text=True, check=True, timeout=60)
    assert out.stdout.strip() == "1"
