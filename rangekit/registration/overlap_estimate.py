"""Which views overlap, estimated cheaply from shared occupied cells (the view graph's overlap chooser).

Every view's points (in the world, at the current poses) are binned into cubic cells; two views'
estimated overlap is the number of cells both occupy over the smaller view's count. One sparse (n, C)
occupancy matrix and its Gram product: no k-d tree, no per-pair query, so all n(n-1)/2 estimates cost
less than one ICP run (the pairs it proposes still get the exact overlap test).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import scipy.sparse as sp

__all__ = ["estimated_overlap", "overlapping_pairs"]


def estimated_overlap(points_world: Sequence[np.ndarray], cell: float) -> np.ndarray:
    """(n, n) estimated overlap fraction of every two views (``points_world``: (N_k, 3) metres in one
    frame; ``cell``: cell edge, metres): shared occupied cells / the smaller view's occupied cells; the
    diagonal is 0."""
    n = len(points_world)
    keys, owner = [], []
    for k, p in enumerate(points_world):
        c = np.unique(np.floor(np.asarray(p, dtype=np.float64) / cell).astype(np.int64), axis=0)
        keys.append(c)
        owner.append(np.full(len(c), k))
    allk = np.concatenate(keys)
    _, col = np.unique(allk, axis=0, return_inverse=True)
    rows = np.concatenate(owner)
    A = sp.csr_matrix((np.ones(len(rows)), (rows, col.ravel())), shape=(n, int(col.max()) + 1 if len(col) else 0))
    G = (A @ A.T).toarray()
    size = np.diag(G).copy()
    out = G / np.maximum(np.minimum(size[:, None], size[None, :]), 1)
    np.fill_diagonal(out, 0.0)
    return out


def overlapping_pairs(points_world: Sequence[np.ndarray], cell: float, m: int,
                      min_fraction: float) -> list[tuple[int, int]]:
    """Each view with its ``m`` most overlapping views (:func:`estimated_overlap`) whose estimate is at
    least ``min_fraction``: the union, ``i < j``; at most ``n m`` pairs."""
    ov = estimated_overlap(points_world, cell)
    n = len(ov)
    top = np.argsort(-ov, axis=1, kind="stable")[:, :min(m, n - 1)]
    return sorted({(min(i, j), max(i, j)) for i in range(n) for j in top[i].tolist() if ov[i, j] >= min_fraction})
