"""Thread hygiene: how many threads the libraries under rangekit may start.

rangekit's numerical work is dominated by thin products, (N, 3) @ (3, 3) transforms and (n, 6)
Jacobians, which OpenBLAS splits over every core: on 2 cores that costs about 5x the CPU of one thread
(issue 20 measured 15% of ``rangekit process``'s CPU; `apply_T` on 200k points: 1.58 CPU-s with two BLAS
threads, 0.31 with one, for 50 calls). So the command line and the long pipelines run with one BLAS
thread (:func:`one_blas_thread`, through threadpoolctl, which finds the BLAS numpy and scipy loaded). The
parallel work is rangekit's own: numba kernels (one thread per core, numba's default), image I/O on a
thread pool, and Open3D's Poisson on a thread of its own beside the evaluation and the report.
scipy's k-d tree queries run with ``workers=1``: ``workers=-1`` starts a new set of threads per query.
"""

from __future__ import annotations

from contextlib import contextmanager

__all__ = ["one_blas_thread"]


@contextmanager
def one_blas_thread():
    """Limit BLAS (OpenBLAS, MKL, BLIS) to one thread inside the block; restored after it."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        yield
