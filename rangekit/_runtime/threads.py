"""Thread hygiene: how many threads the libraries under rangekit may start.

rangekit's numerical work is dominated by thin products, (N, 3) @ (3, 3) transforms and (n, 6)
Jacobians, which OpenBLAS splits over every core. On an idle machine a second BLAS thread buys nothing for
them and costs CPU (`apply_T` on 1.3M points: 13.8 CPU-ms on one thread, 18.9 on two;
``benchmarks/app/bench_process_parts.py``); beside other work its spinning threads cost far more (on the
loaded 2-core machine ``rangekit process`` of the 12-view scan, under cProfile, took 138 CPU-s, and 84 with
``OPENBLAS_NUM_THREADS=1``). So the command line and the long pipelines run with one BLAS
thread (:func:`one_blas_thread`, through threadpoolctl, which finds the BLAS numpy and scipy loaded). The
parallel work is rangekit's own: numba kernels (one thread per core, numba's default), image I/O on a
thread pool, and Open3D's Poisson on a thread of its own beside the evaluation and the report.
scipy's k-d tree queries run with ``workers=1``: ``workers=-1`` starts a new set of threads per query.
"""

from __future__ import annotations

from contextlib import contextmanager

__all__ = ["one_blas_thread", "numba_threads"]


@contextmanager
def one_blas_thread():
    """Limit BLAS (OpenBLAS, MKL, BLIS) to one thread inside the block; restored after it."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        yield


@contextmanager
def numba_threads(n: int):
    """numba's parallel kernels on at most ``n`` threads inside the block, on this thread only (numba's setting is
    per thread; the OpenMP threading layer takes launches from several threads at once): two views decoded on
    two threads with one numba thread each used 1.9 cores where one view on two numba threads used 1.5
    (:mod:`rangekit.app.process.view_cache`)."""
    import numba

    before = numba.get_num_threads()
    numba.set_num_threads(max(1, min(n, before)))
    try:
        yield
    finally:
        numba.set_num_threads(before)
