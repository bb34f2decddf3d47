"""Give the C heap's free pages back to the OS after a split (glibc ``malloc_trim``).

Why: measured in the node (two encoders, 1 kHz, split every minute, ``SSI_BRIDGE_MEMPROBE``):
the Python heap (tracemalloc) and the bytes malloc has in use stay flat, but each split
leaves ~0.3 MB more *free* memory inside glibc's arenas (the last chunk compressed, the
summary built and the next file's writer allocated on whichever executor thread wrote the
message that split), below live blocks, so glibc's automatic trim (top of the heap only)
cannot return it and RSS grew ~4.5 MB per 10 min. ``malloc_trim(0)`` releases every free
page of every arena (madvise), once per split, on the flush thread. Elsewhere than glibc
(musl, macOS) this is a no-op; ``SSI_BRIDGE_MALLOC_TRIM=0`` turns it off (to measure the
difference with ``make bench ONLY=soak``).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import logging
import os
import time

logger = logging.getLogger(__name__)


@functools.cache
def _malloc_trim() -> ctypes._CFuncPtr | None:  # type: ignore[name-defined]
    """glibc's ``malloc_trim``, or None where the C library has none."""
    name = ctypes.util.find_library("c")
    if name is None or os.environ.get("SSI_BRIDGE_MALLOC_TRIM", "1") == "0":
        return None
    try:
        trim = ctypes.CDLL(name).malloc_trim
    except (OSError, AttributeError):
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


def release_free_memory() -> bool:
    """Return free heap pages to the OS; True if glibc released any."""
    trim = _malloc_trim()
    if trim is None:
        return False
    start = time.monotonic()
    released = bool(trim(0))
    logger.debug("malloc_trim: %.1f ms, released: %s", (time.monotonic() - start) * 1e3,
                 released)
    return released
