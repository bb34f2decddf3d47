"""Give the C heap's free pages back to the OS after a split (glibc ``malloc_trim``).

A split leaves free memory inside glibc's arenas below live blocks, which glibc's automatic
trim (top of a heap only) cannot return, so the RSS of a long recording would grow with
every split (the measurements: docs/recording.md "Memory over hours"). ``malloc_trim(0)``
releases every free page of every arena (madvise), once per split, on the flush thread.
Elsewhere than glibc (musl, macOS) this is a no-op; ``SSI_BRIDGE_MALLOC_TRIM=0`` turns it
off (to measure the difference with ``make bench ONLY=soak``).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import logging
import os
import time

logger = logging.getLogger(__name__)


#: glibc's mallopt parameter for the number of malloc arenas, and the node's limit
M_ARENA_MAX = -8
MALLOC_ARENA_MAX = 2
#: glibc's mallopt parameter for the mmap threshold, and the node's: glibc's initial value,
#: fixed
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD = 128 * 1024


@functools.cache
def libc() -> ctypes.CDLL | None:
    """The C library (malloc and its tuning live there), or None where it cannot be loaded."""
    name = ctypes.util.find_library("c")
    try:
        return ctypes.CDLL(name) if name else None
    except OSError:
        return None


@functools.cache
def _malloc_trim() -> ctypes._CFuncPtr | None:  # type: ignore[name-defined]
    """glibc's ``malloc_trim``, or None where the C library has none."""
    lib = libc()
    if lib is None or os.environ.get("SSI_BRIDGE_MALLOC_TRIM", "1") == "0":
        return None
    try:
        trim = lib.malloc_trim
    except AttributeError:
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


def limit_malloc_arenas(limit: int = MALLOC_ARENA_MAX) -> None:
    """At most ``limit`` glibc malloc arenas (default 8 per core); call before threads start.

    A recording node's RSS grew by the free memory left in each thread's arena at every split
    (docs/node.md, "Memory"); with fewer arenas that memory is reused by the other threads.
    ``MALLOC_ARENA_MAX`` in the environment wins; not glibc: nothing to do.
    """
    _mallopt_unless_set("MALLOC_ARENA_MAX", M_ARENA_MAX, limit)


def fix_mmap_threshold(threshold: int = MMAP_THRESHOLD) -> None:
    """Blocks of ``threshold`` bytes or more get their own mmap, for the whole run.

    glibc starts at 128 kB but raises the threshold to the size of every mmapped block that is
    freed (up to 32 MB), so after start-up the few-hundred-kB blocks of a recording (a
    chunk's compressed bytes, a buffer that grows) come from the heap, where they leave free
    memory between longer-lived blocks (the measurements: docs/recording.md "Memory over
    hours"). Setting it turns glibc's adjustment off; a
    ``MALLOC_MMAP_THRESHOLD_`` in the environment wins; not glibc: nothing to do.
    """
    _mallopt_unless_set("MALLOC_MMAP_THRESHOLD_", M_MMAP_THRESHOLD, threshold)


def _mallopt_unless_set(variable: str, param: int, value: int) -> None:
    """glibc ``mallopt(param, value)`` unless the environment sets ``variable`` (it wins);
    nothing where the C library has no mallopt."""
    if variable in os.environ:
        return
    mallopt = getattr(libc(), "mallopt", None)
    if mallopt is not None:
        mallopt(param, value)


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
