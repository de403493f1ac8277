"""Give freed memory back to the operating system.

glibc keeps the pages of freed heap blocks (and, after a large block is freed, raises its mmap threshold so
later large arrays come from the heap too): after decoding twelve views, or after Open3D's Poisson octree is
freed on the fusion thread, the process keeps hundreds of MB it no longer uses, and the next stage's
allocations (on another thread's arena) come on top. :func:`release_free_memory` calls ``malloc_trim(0)``
(every arena) where a stage has just freed a lot; it changes no result. A no-op without glibc, and in a
process started with one arena (``MALLOC_ARENA_MAX=1``, as rangekit's Dask workers are,
:data:`rangekit.app.batch.WORKER_MALLOC`): there every thread reuses the freed pages, and trimming them would
only make the next stage or task fault them in again.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os

__all__ = ["release_free_memory"]

_LIBC_NAME = ctypes.util.find_library("c")
_MALLOC_TRIM = getattr(ctypes.CDLL(_LIBC_NAME), "malloc_trim", None) if _LIBC_NAME else None
#: glibc reads MALLOC_ARENA_MAX when the process starts: set then, it holds for the whole process.
_ONE_ARENA = os.environ.get("MALLOC_ARENA_MAX") == "1"


def release_free_memory() -> None:
    """Return the free pages of every malloc arena to the OS (glibc ``malloc_trim(0)``; nothing without glibc or
    with one arena)."""
    if _MALLOC_TRIM is not None and not _ONE_ARENA:
        _MALLOC_TRIM(0)
