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
"Minor page faults" of ``/usr/bin/time -v rangekit decode ...`` show it). A worker thread's arena is made of
64 MB heaps that glibc unmaps as soon as one is wholly free, whatever the trim threshold, so inside the block
the top pad is raised to a heap's size, which keeps them. A block larger than a heap (a view's frame stack:
48-60 frames of 1280x1024 are 63-79 MB) is mapped on its own on a worker thread whatever the threshold:
:func:`reused_array` keeps one per thread for the next view where a stage asks for it (the scan's frames read
ahead, :mod:`rangekit.app.scan.frames_ahead`; the batch decode reads each view into a fresh one, whose pages go
when the view is decoded: kept, they raised ``rangekit process``'s peak); :func:`adopt_kept` hands a thread's on
to the thread that takes over its work (the scan's last view, decoded on the caller's thread once the streaming
worker has ended). On leaving the outermost block, glibc's limits are set to where its own adjustment takes them (32 MB), the top pad to its default, the kept arrays dropped and
the free pages returned. Blocks may nest and overlap on several threads: the settings hold until the last one
ends. Inside, numpy's advice for huge pages on its large arrays is off too: the pages the block does fault in
(its first view's) then come 4 kB at a time; as 2 MB huge pages the kernel spent about 4x the system time
zeroing them (``perf``: ``clear_page_erms`` under ``do_huge_pmd_anonymous_page``; the decode of the 12-view
default session, issue 51).
"""

from __future__ import annotations

import ctypes
import gc
import os
import sys
import threading
from contextlib import contextmanager
from typing import Callable

import numpy as np

__all__ = ["release_free_memory", "reuse_freed_memory", "reused_array", "adopt_kept", "forgettable_cache", "forget_caches"]

try:
    _LIBC = ctypes.CDLL(None)   # the process's own symbols: libc's, without a search (ldconfig) for it
except OSError:
    _LIBC = None
_MALLOC_TRIM = getattr(_LIBC, "malloc_trim", None)
_MALLOPT = getattr(_LIBC, "mallopt", None)
#: glibc reads MALLOC_ARENA_MAX when the process starts: set then, it holds for the whole process.
_ONE_ARENA = os.environ.get("MALLOC_ARENA_MAX") == "1"
#: mallopt's parameters (glibc's malloc.h).
_M_TRIM_THRESHOLD, _M_TOP_PAD, _M_MMAP_THRESHOLD = -1, -2, -3
#: Where glibc's own adjustment of the mmap threshold stops (DEFAULT_MMAP_THRESHOLD_MAX on 64-bit).
_MMAP_THRESHOLD_MAX = 32 * 2**20
#: glibc's own top pad (DEFAULT_TOP_PAD) and the size of a worker thread's heap (HEAP_MAX_SIZE on 64-bit).
_DEFAULT_TOP_PAD, _HEAP_BYTES = 128 * 2**10, 2 * _MMAP_THRESHOLD_MAX
#: Arrays up to this size come from the heap inside :func:`reuse_freed_memory`.
REUSE_BYTES = 256 * 2**20

#: numpy's switch for madvise(MADV_HUGEPAGE) on its large arrays (numpy 2: np._core; 1.x: np.core).
_MULTIARRAY = getattr(getattr(np, "_core", None), "multiarray", None) or np.core.multiarray
_SET_HUGEPAGE = getattr(_MULTIARRAY, "_set_madvise_hugepage", None)

_LOCK = threading.Lock()
_OPEN = 0                                        # reuse blocks open, on every thread
_KEPT: dict[tuple[int, str], np.ndarray] = {}    # (thread ident, name) -> the array reused_array keeps


#: The clearing functions of the caches of large arrays (:func:`forgettable_cache`).
_CACHES: list[Callable[[], None]] = []


def forgettable_cache(clear: Callable[[], None]) -> Callable[[], None]:
    """Register ``clear``, which empties a module's cache of large arrays (the per-pixel rays, the boards'
    textures), with :func:`forget_caches`; returns it."""
    _CACHES.append(clear)
    return clear


def forget_caches() -> None:
    """Empty every registered cache (:func:`forgettable_cache`), collect the cycles and return the free pages
    (:func:`release_free_memory`): where a long-lived process finished a piece of work whose rigs and boards
    the next one may not share (a job of ``rangekit ui``, a test module). The next call that needs a cached
    array computes it again, the same bytes."""
    for clear in list(_CACHES):
        clear()
    gc.collect()
    release_free_memory()


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
    global _OPEN
    if _MALLOPT is None or _ONE_ARENA or "MALLOC_MMAP_THRESHOLD_" in os.environ:
        yield
        return
    with _LOCK:
        _OPEN += 1
        if _OPEN == 1:
            _huge_pages(False)
            _MALLOPT(_M_MMAP_THRESHOLD, int(limit))
            _MALLOPT(_M_TRIM_THRESHOLD, 2 * int(limit))
            _MALLOPT(_M_TOP_PAD, _HEAP_BYTES)
    try:
        yield
    finally:
        with _LOCK:
            _OPEN -= 1
            last = _OPEN == 0
            if last:
                _KEPT.clear()
                _MALLOPT(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD_MAX)
                _MALLOPT(_M_TRIM_THRESHOLD, 2 * _MMAP_THRESHOLD_MAX)
                _MALLOPT(_M_TOP_PAD, _DEFAULT_TOP_PAD)
                _huge_pages(True)
        if last:
            release_free_memory()


_HUGE_BEFORE = [True]


def _huge_pages(on: bool) -> None:
    """numpy's huge-page advice off (remembering what it was), or back to what it was."""
    if _SET_HUGEPAGE is None:
        return
    if not on:
        _HUGE_BEFORE[0] = bool(_SET_HUGEPAGE(False))   # returns the previous setting
    else:
        _SET_HUGEPAGE(_HUGE_BEFORE[0])


def reused_array(name: str, shape: tuple[int, ...], dtype) -> np.ndarray:
    """An uninitialised array of ``shape`` and ``dtype``: inside :func:`reuse_freed_memory`, the one this thread
    last had under ``name`` when its shape and dtype are these and nothing holds it or a view of it any more (its
    pages already faulted in; its old contents left, the caller overwrites them), else a new one kept for next
    time; outside a block always a new one, nothing kept. For a large array made again and again on a worker
    thread (a view's frame stack): glibc maps such a block afresh each time (module doc)."""
    dtype = np.dtype(dtype)
    shape = tuple(int(n) for n in shape)
    key = (threading.get_ident(), name)
    with _LOCK:
        if _OPEN == 0:
            return np.empty(shape, dtype)
        kept = _KEPT.pop(key, None)
    # held by this frame and getrefcount's argument alone: no caller and no view (a view holds its base) left
    if kept is None or kept.shape != shape or kept.dtype != dtype or sys.getrefcount(kept) > 2:
        kept = None     # dropped here, before its replacement is made: not both at once
        kept = np.empty(shape, dtype)
    with _LOCK:
        if _OPEN > 0:
            _KEPT[key] = kept
    return kept


def adopt_kept(thread_ident: int) -> int:
    """The arrays :func:`reused_array` keeps for thread ``thread_ident`` (one that has ended, or handed its work on
    to this one) become this thread's: its next :func:`reused_array` of the same name, shape and dtype takes them,
    pages already faulted in (the scan's last view, decoded on the caller's thread after the streaming worker's
    earlier views: :class:`rangekit.app.runner.StreamingWorker`). Returns how many were handed on (0 outside a
    block, or with none kept); an array this thread keeps under the same name is dropped for it."""
    me = threading.get_ident()
    if thread_ident == me:
        return 0
    with _LOCK:
        names = [name for ident, name in _KEPT if ident == thread_ident]
        for name in names:
            _KEPT[(me, name)] = _KEPT.pop((thread_ident, name))
    return len(names)
