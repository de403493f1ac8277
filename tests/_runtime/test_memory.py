"""rangekit._runtime.memory against glibc's own counters (mallinfo2): inside reuse_freed_memory a large array comes from
the heap, after it from its own mapping again, and a process started with its malloc settings keeps them.
Each case runs in a fresh interpreter with glibc's own settings (the suite's ``MALLOC_*`` variables left out),
so the suite's own allocator is left as it was."""

import os
import subprocess
import sys
import textwrap

import pytest

PROBE = textwrap.dedent("""
    import ctypes, numpy as np
    from rangekit._runtime.memory import reuse_freed_memory

    class Info(ctypes.Structure):
        _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                                    "fsmblks", "uordblks", "fordblks", "keepcost")]
    libc = ctypes.CDLL(None)
    libc.mallinfo2.restype = Info

    def mapped(n_bytes):
        # bytes in blocks of their own mapping while an array of n_bytes is alive
        a = np.ones(n_bytes, dtype=np.uint8)
        out = libc.mallinfo2().hblkhd
        del a
        return out

    base = libc.mallinfo2().hblkhd
    with reuse_freed_memory():
        inside = mapped(64 << 20) - base
    after = mapped(64 << 20) - base
    print(inside >= 64 << 20, after >= 64 << 20)
""")


def _glibc_defaults(env: dict | None = None) -> dict:
    """This process's environment without the ``MALLOC_*`` settings (``make test`` sets one), with ``env``."""
    return {**{k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}, **(env or {})}


def probe(env=None) -> str:
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=120,
                         env=_glibc_defaults(env))
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


@pytest.fixture(autouse=True)
def glibc():
    import ctypes

    if not hasattr(ctypes.CDLL(None), "mallinfo2"):
        pytest.skip("glibc 2.33 or later (mallinfo2) needed to see where malloc put a block")


def test_inside_the_block_a_64_mb_array_comes_from_the_heap_and_after_it_from_its_own_mapping():
    assert probe() == "False True"


def test_a_process_started_with_its_malloc_settings_keeps_them():
    # a 1 MB threshold set at start (as the Dask workers get theirs): the block must not lift it
    assert probe({"MALLOC_MMAP_THRESHOLD_": str(1 << 20)}) == "True True"


HEAP_PROBE = textwrap.dedent("""
    import ctypes, sys, threading, numpy as np
    from contextlib import nullcontext
    from rangekit._runtime.memory import reuse_freed_memory

    class Info(ctypes.Structure):
        _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                                    "fsmblks", "uordblks", "fordblks", "keepcost")]
    libc = ctypes.CDLL(None)
    libc.mallinfo2.restype = Info
    dropped = []

    def on_a_thread():
        # 20 MB blocks on a worker thread's own arena (several of its 64 MB heaps), all freed: bytes unmapped
        blocks = [np.ones(20 << 20, dtype=np.uint8) for _ in range(8)]
        before = libc.mallinfo2().arena
        del blocks
        dropped.append(before - libc.mallinfo2().arena)

    if sys.argv[1] == "after":      # the block's 32 MB mmap threshold left, its top pad not
        with reuse_freed_memory():
            pass
    with reuse_freed_memory() if sys.argv[1] == "inside" else nullcontext():
        t = threading.Thread(target=on_a_thread)
        t.start()
        t.join()
    print(dropped[0] >> 20)
""")


def heap_probe(where: str) -> int:
    out = subprocess.run([sys.executable, "-c", HEAP_PROBE, where], capture_output=True, text=True, timeout=120,
                         env=_glibc_defaults())
    assert out.returncode == 0, out.stderr
    return int(out.stdout)


def test_inside_the_block_a_worker_threads_freed_heaps_are_kept_and_after_it_unmapped():
    # glibc unmaps a thread arena's heap once it is wholly free, whatever the trim threshold: the next view's
    # arrays would fault its pages in again (rangekit._runtime.memory's doc)
    assert heap_probe("inside") == 0
    assert heap_probe("after") >= 20   # at least one wholly free heap unmapped


def test_reused_array_gives_a_threads_last_array_back_only_inside_the_block_and_only_when_free():
    import threading

    import numpy as np

    from rangekit._runtime import memory
    from rangekit._runtime.memory import reuse_freed_memory, reused_array

    if memory._MALLOPT is None or memory._ONE_ARENA or "MALLOC_MMAP_THRESHOLD_" in os.environ:
        pytest.skip("the block changes nothing in this process")
    a = reused_array("t", (4, 5), np.uint8)
    assert reused_array("t", (4, 5), np.uint8) is not a        # outside a block: a new one each time
    with reuse_freed_memory():
        a = reused_array("t", (4, 5), np.uint8)
        first = id(a)
        del a
        b = reused_array("t", (4, 5), np.uint8)
        assert id(b) == first                                   # the same array, free again
        view = b[1:]
        del b
        c = reused_array("t", (4, 5), np.uint8)
        assert id(c) != first and c.base is None                # a view still holds it: a new one
        assert view.base is not c
        del view
        assert reused_array("t", (4, 6), np.uint8).shape == (4, 6)    # another shape: a new one
        other = []
        t = threading.Thread(target=lambda: other.append(reused_array("t", (4, 6), np.uint8)))
        t.start()
        t.join()
        assert other[0] is not reused_array("t", (4, 6), np.uint8)   # each thread its own
        del other
        with reuse_freed_memory():                              # nested: the outer block still holds it
            pass
        assert memory._KEPT
    assert not memory._KEPT                                     # dropped when the last block ends


def test_numpys_huge_page_advice_is_off_inside_the_block_and_as_it_was_after():
    import numpy as np

    from rangekit._runtime import memory
    from rangekit._runtime.memory import reuse_freed_memory

    if memory._SET_HUGEPAGE is None or memory._MALLOPT is None or memory._ONE_ARENA \
            or "MALLOC_MMAP_THRESHOLD_" in os.environ:
        pytest.skip("the block changes nothing in this process")
    get = np._core.multiarray._get_madvise_hugepage
    was = get()
    with reuse_freed_memory():
        with reuse_freed_memory():
            assert get() is False
        assert get() is False
    assert get() == was


def test_adopt_kept_hands_a_threads_kept_array_to_the_thread_that_takes_over_its_work():
    """The scan's last view is decoded on the caller's thread once the streaming worker has ended: it takes the
    worker's frame stack, its pages faulted in (rangekit.app.runner.StreamingWorker); outside a block nothing is
    kept to hand on."""
    import threading

    import numpy as np

    from rangekit._runtime import memory
    from rangekit._runtime.memory import adopt_kept, reuse_freed_memory, reused_array

    if memory._MALLOPT is None or memory._ONE_ARENA or "MALLOC_MMAP_THRESHOLD_" in os.environ:
        pytest.skip("the block changes nothing in this process")
    ident, made = [], []

    def worker():
        ident.append(threading.get_ident())
        made.append(id(reused_array("frames0", (48, 8, 8), np.uint8)))   # freed at once: kept for the thread

    t = threading.Thread(target=worker)
    t.start()
    t.join()
    assert adopt_kept(ident[0]) == 0                                    # outside a block: nothing was kept
    with reuse_freed_memory():
        t = threading.Thread(target=worker)
        t.start()
        t.join()
        assert reused_array("frames0", (48, 8, 8), np.uint8) is not None and len(memory._KEPT) == 2
        assert adopt_kept(ident[1]) == 1 and adopt_kept(threading.get_ident()) == 0
        assert id(reused_array("frames0", (48, 8, 8), np.uint8)) == made[1]   # the worker's array, taken over
        assert len(memory._KEPT) == 1
    assert not memory._KEPT


def test_forget_caches_empties_the_rays_and_the_board_textures_and_they_come_back_the_same():
    """One call empties every registered cache of large arrays (rangekit ui after a job, the suite between
    modules); the next call that needs one makes the same bytes again."""
    import numpy as np

    from rangekit import boards, camera
    from rangekit._runtime import memory
    from rangekit._runtime.memory import forget_caches, forgettable_cache
    from rangekit.sim import default_rig
    from rangekit.sim.scene import objects

    cam = default_rig().camera
    rays = camera.pixel_rays(cam)
    board = boards.Board()
    texture = board.texture(board.square / 20)
    objects._board_texture(board, board.square / 20)
    called = []
    clear = forgettable_cache(lambda: called.append(1))
    try:
        forget_caches()
    finally:
        memory._CACHES.remove(clear)
    assert called == [1] and not camera._RAY_CACHE
    assert boards._texture.cache_info().currsize == 0 and objects._board_texture.cache_info().currsize == 0
    again = camera.pixel_rays(cam)
    assert again is not rays
    np.testing.assert_array_equal(again, rays)
    np.testing.assert_array_equal(board.texture(board.square / 20)[0], texture[0])
