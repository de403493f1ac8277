"""rangekit._runtime.noalias: the flag reaches LLVM (each array argument's data pointer is ``noalias``), and a
flagged function computes what the same function computes unflagged."""

import numba
import numpy as np

from rangekit._runtime.noalias import njit_noalias


def _shifted_min(src, dst):
    for k in range(dst.shape[0]):
        dst[k] = min(src[k], src[k + 1])


def test_array_arguments_are_noalias_in_llvm():
    flagged, plain = njit_noalias()(_shifted_min), numba.njit(_shifted_min)
    src, dst = np.arange(9, dtype=np.int16)[::-1].copy(), np.empty(8, np.int16)
    flagged(src, dst)
    plain(src, dst)

    def data_pointer_attributes(fn, name):
        """The LLVM attributes of the array argument's data pointer (numba's array struct, field 4)."""
        ir = next(iter(fn.inspect_llvm().values()))
        define = next(line for line in ir.splitlines() if line.startswith("define") and "_shifted_min" in line)
        return next(p for p in define.split(", ") if p.endswith(f"%arg.{name}.4")).split()

    for name in ("src", "dst"):
        assert "noalias" in data_pointer_attributes(flagged, name)
        assert "noalias" not in data_pointer_attributes(plain, name)


def test_flagged_function_gives_the_same_result():
    src = np.random.default_rng(0).integers(-100, 100, 101).astype(np.int16)
    a, b = np.empty(100, np.int16), np.empty(100, np.int16)
    njit_noalias()(_shifted_min)(src, a)
    numba.njit(_shifted_min)(src, b)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, np.minimum(src[:-1], src[1:]))
