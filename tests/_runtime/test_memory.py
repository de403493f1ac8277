"""rangekit._runtime.memory against glibc's own counters (mallinfo2): inside reuse_freed_memory a large array comes from
the heap, after it from its own mapping again, and a process started with its malloc settings keeps them.
Each case runs in a fresh interpreter, so the suite's own allocator is left as it was."""

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


def probe(env=None) -> str:
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=120,
                         env={**os.environ, **(env or {})})
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
