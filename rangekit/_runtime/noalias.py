"""``njit_noalias``: numba's ``njit`` with every array argument marked ``noalias`` (C's ``restrict``).

Why: when a loop stores into one array and loads from others, LLVM can only vectorise it after checking
at run time that the arrays do not overlap, pairwise, every time the loop starts. numba gives LLVM no
aliasing facts about its array arguments, so a short loop that reads 8 rows and writes 5 (census-SGM's 4
paths at one pixel, ``rangekit.stereo._sgm``) spent more time in those checks, and in reloading the
addresses they need, than in its 64 disparities: ``sgm_match`` (cost, aggregation, winner-take-all) took
41 ms on one thread on the 640x400 benchmark pair before commit 40c1f3c, and 22 ms with its rows passed as
``noalias`` arguments, with the same disparities (``python benchmarks/stereo/bench_stereo.py --parts`` times it).

numba already has the switch: the compiler flag ``noalias``, which it sets for its own parallel loop
bodies (``numba.parfors``). ``njit`` has no option for it, so this module sets the flag in a compiler
pipeline (``pipeline_class``, numba's documented hook for custom pipelines). The promise is the
caller's: no two arguments of such a function may share memory that the function writes. Views of one
array passed as two arguments break it, silently. So keep such a function small, call it with buffers
it owns, and check it against an unflagged reference (tests/stereo/test_stereo_sgm.py does).
"""

from __future__ import annotations

from numba import njit
from numba.core.compiler import Compiler

__all__ = ["NoAliasCompiler", "njit_noalias"]


class NoAliasCompiler(Compiler):
    """numba's default pipeline with the ``noalias`` flag set: LLVM sees each array argument's data
    pointer as ``noalias``."""

    def __init__(self, typingctx, targetctx, library, args, return_type, flags, locals):
        flags.noalias = True
        super().__init__(typingctx, targetctx, library, args, return_type, flags, locals)


def njit_noalias(**options):
    """``numba.njit(**options)`` compiled with :class:`NoAliasCompiler` (no argument may overlap another
    that the function writes)."""
    return njit(pipeline_class=NoAliasCompiler, **options)
