"""Which pairs coarse alignment tries when there is no prior: O(n k), not all n(n-1)/2.

Every view gets a cheap global descriptor, the mean of its FPFH features (the features coarse alignment
computes anyway) normalised to sum 1, and views are compared by the chi-square distance of their
descriptors. Overlapping views see the same patches of surface, so their feature distributions agree. On
the Stanford bunny's 10 scans each view's 4 most similar give 24 pairs, 20 of them overlapping by 30% or
more at bun.conf's poses (a D2 shape distribution gave 22 of 29, a 64-word bag of FPFH words 20 of 27:
no better for more work; docs/registration.md).

:func:`coarse_graph` aligns each view with its ``k`` most similar, then, while the accepted edges leave
the views in several components, each view with its most similar untried partner in another component,
until the graph is connected or every pair has been tried (union-find).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from rangekit.errors import InputError, RegistrationError

__all__ = ["view_descriptor", "descriptor_distances", "similar_pairs", "coarse_graph", "widen_until_settled", "Components"]


def view_descriptor(fpfh: np.ndarray) -> np.ndarray:
    """(D,) global descriptor of a view from its (N, D) FPFH features: their mean, normalised to sum 1."""
    m = np.asarray(fpfh, dtype=np.float64).mean(axis=0)
    return m / max(float(m.sum()), 1e-300)


def descriptor_distances(desc: np.ndarray) -> np.ndarray:
    """(n, n) chi-square distances between the rows of ``desc`` (n, D) (non-negative, each summing to 1);
    the diagonal is +inf (a view is not its own partner)."""
    X = np.asarray(desc, dtype=np.float64)
    num = (X[:, None, :] - X[None, :, :]) ** 2
    den = X[:, None, :] + X[None, :, :]
    d = 0.5 * np.sum(np.divide(num, den, out=np.zeros_like(num), where=den > 0), axis=2)
    np.fill_diagonal(d, np.inf)
    return d


def similar_pairs(dist: np.ndarray, k: int) -> list[tuple[int, int]]:
    """Each view with its ``k`` nearest by ``dist`` (n, n) (ties by index): the union, ``i < j``."""
    if not (isinstance(k, (int, np.integer)) and k >= 1):
        raise InputError(f"similar_pairs: k must be an integer >= 1, found {k!r}")
    n = len(dist)
    near = np.argsort(dist, axis=1, kind="stable")[:, :min(k, n - 1)]
    return sorted({(min(i, j), max(i, j)) for i in range(n) for j in near[i].tolist()})


class Components:
    """Union-find over n views (path halving)."""

    def __init__(self, n: int):
        self.parent = list(range(n))

    def find(self, a: int) -> int:
        p = self.parent
        while p[a] != a:
            p[a] = p[p[a]]
            a = p[a]
        return a

    def join(self, a: int, b: int) -> None:
        self.parent[self.find(a)] = self.find(b)

    def count(self) -> int:
        return len({self.find(a) for a in range(len(self.parent))})


def coarse_graph(dist: np.ndarray, k: int, align: Callable[[int, int], object]) -> list:
    """Try pairs until the accepted ones connect the views; returns every result of ``align`` in order.

    ``dist``: (n, n) descriptor distances (:func:`descriptor_distances`); ``k``: pairs per view first;
    ``align(i, j)`` (``i < j``) registers the pair and returns an object with a bool ``accepted``.
    Then, while the accepted edges leave several components, each view is tried with its nearest untried
    partner in another component (a pair whose views got joined meanwhile is skipped); it stops when one
    component is left or no untried pair joins two components. The caller checks connectivity (and
    names the views cut off).
    """
    n = len(dist)
    comp = Components(n)
    tried: set = set()
    out = []

    def run(i: int, j: int) -> None:
        tried.add((i, j))
        r = align(i, j)
        out.append(r)
        if r.accepted:
            comp.join(i, j)

    for i, j in similar_pairs(dist, k):
        run(i, j)
    order = np.argsort(dist, axis=1, kind="stable")[:, :n - 1]
    while comp.count() > 1:
        wanted = []
        for a in range(n):
            for b in order[a].tolist():
                p = (min(a, b), max(a, b))
                if p not in tried and p not in wanted and comp.find(a) != comp.find(b):
                    wanted.append(p)
                    break
        if not wanted:
            break
        for i, j in wanted:
            if comp.find(i) != comp.find(j):
                run(i, j)
    return out


def widen_until_settled(dist: np.ndarray, k: int, align: Callable[[int, int], object],
                        settle: Callable[[list], object]) -> tuple[list, object, int]:
    """:func:`coarse_graph` with ``k``, then 2k, 4k, ... (each pair aligned once) until ``settle(results)``
    (the connectivity check and the robust synchronisation, over every pair aligned so far) stops raising
    RegistrationError; re-raises it when k has reached n - 1. Returns (results, settle's value, k used).

    A connected graph can still fail the robust synchronisation: on the 36-view turntable the 4 most
    similar gave a chain with bridges, and rejecting 4 inconsistent edges cut views 9-31 off."""
    cache: dict = {}

    def once(i: int, j: int):
        if (i, j) not in cache:
            cache[i, j] = align(i, j)
        return cache[i, j]

    n = len(dist)
    while True:
        coarse_graph(dist, k, once)
        results = [cache[p] for p in sorted(cache)]
        try:
            return results, settle(results), k
        except RegistrationError:
            if k >= n - 1:
                raise
            k = min(2 * k, n - 1)
