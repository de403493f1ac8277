"""Give freed memory back to the operating system, or keep it for reuse where a stage frees and allocates the
same large arrays again and again.

glibc keeps the pages of freed heap blocks (and, after a large block is freed, raises its mmap threshold so
later large arrays come from the heap too): after decoding twelve views, or after Open3D's Poisson octree is
freed on the fusion thread, the process keeps hundreds of MB it no longer uses, and the next stage's
allocations (on another thread's arena) come on top. :func:`release_free_memory` calls ``malloc_trim(0)``
(every arena) where a stage has just freed a lot; it changes no result. A no-op without glibc, and in a
process started with one arena (``MALLOC_ARENA_MAX=1``, as rangekit's Dask workers are,
:data:`rangekit.app.batch.sessions.WORKER_MALLOC`): there every thread reuses the freed pages, and trimming them would
only make the next stage or task fault them in again.

The other way round, :func:`reuse_freed_memory`: inside its block arrays up to a threshold come from the heap
and freed ones stay there, so a decoder's temporaries (tens of MB each, allocated and freed many times per
view) reuse pages instead of mapping fresh ones that the kernel must fault in and zero (the system time and
"Minor page faults" of ``/usr/bin/time -v rangekit decode ...`` show it). On leaving, glibc's limits are set
to where its own adjustment takes them (32 MB) and the free pages are returned.
"""

from __future__ import annotations

import ctypes
import os
from contextlib import contextmanager

__all__ = ["release_free_memory", "reuse_freed_memory"]

try:
    _LIBC = ctypes.CDLL(None)   # the process's own symbols: libc's, without a search (ldconfig) for it
except OSError:
    _LIBC = None
_MALLOC_TRIM = getattr(_LIBC, "malloc_trim", None)
_MALLOPT = getattr(_LIBC, "mallopt", None)
#: glibc reads MALLOC_ARENA_MAX when the process starts: set then, it holds for the whole process.
_ONE_ARENA = os.environ.get("MALLOC_ARENA_MAX") == "1"
#: mallopt's parameters (glibc's malloc.h).
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
#: Where glibc's own adjustment of the mmap threshold stops (DEFAULT_MMAP_THRESHOLD_MAX on 64-bit).
_MMAP_THRESHOLD_MAX = 32 * 2**20
#: Arrays up to this size come from the heap inside :func:`reuse_freed_memory`.
REUSE_BYTES = 256 * 2**20


def release_free_memory() -> None:
    """Return the free pages of every malloc arena to the OS (glibc ``malloc_trim(0)``; nothing without glibc or
    with one arena)."""
    if _MALLOC_TRIM is not None and not _ONE_ARENA:
        _MALLOC_TRIM(0)


@contextmanager
def reuse_freed_memory(limit: int = REUSE_BYTES):
    """Inside the block, arrays up to ``limit`` bytes come from the heap and freed pages stay there for the
    next array (glibc ``mallopt``); on leaving, the limits go to 32 MB (where glibc's own adjustment ends)
    and the free pages are returned (:func:`release_free_memory`). Nothing without glibc, and nothing where
    the process was started with its malloc settings (the Dask workers: ``MALLOC_ARENA_MAX``,
    ``MALLOC_MMAP_THRESHOLD_``), which it keeps."""
    if _MALLOPT is None or _ONE_ARENA or "MALLOC_MMAP_THRESHOLD_" in os.environ:
        yield
        return
    _MALLOPT(_M_MMAP_THRESHOLD, int(limit))
    _MALLOPT(_M_TRIM_THRESHOLD, 2 * int(limit))
    try:
        yield
    finally:
        _MALLOPT(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD_MAX)
        _MALLOPT(_M_TRIM_THRESHOLD, 2 * _MMAP_THRESHOLD_MAX)
        release_free_memory()
