"""Mesh topology on integer arrays, vectorised: distinct rows, edges, and the watertight test.

- :func:`unique_rows`: distinct rows of an (N, K) int array numbered by first occurrence (one 1-D sort of a
  packed key instead of a K-key ``lexsort``).
- :func:`directed_edges`: the (3F, 2) edges a->b of a face array, in face order.
- :func:`merged_vertex_ids`: vertices that agree to 1e-8 m share an id (trimesh's ``merge_vertices``).
- :func:`is_closed_manifold`: trimesh's ``is_watertight and is_winding_consistent`` after merging, without
  building a trimesh (on the 900k-triangle closed scan: 0.15 s against trimesh's 0.9 s).
"""

from __future__ import annotations

import numpy as np

__all__ = ["MERGE_SCALE", "stable_order", "unique_rows", "directed_edges", "merged_vertex_ids", "is_closed_manifold"]

#: Vertices whose coordinates (metres) round to the same multiple of 1/MERGE_SCALE are one vertex (trimesh's
#: ``tol.merge`` = 1e-8).
MERGE_SCALE = 1e8
_KEY_LIMIT = 2 ** 62


def _packed_key(a: np.ndarray) -> np.ndarray:
    """(N,) int64 >= 0, equal exactly where the rows of the (N, K) int array ``a`` are equal: the columns
    packed left to right, the packed prefix replaced by its ranks (one sort) whenever the next column
    would overflow (rounded vertex coordinates: x and y packed, ranked, then z)."""
    a = a.astype(np.int64, copy=False)
    key, span = None, 1
    for j in range(a.shape[1]):
        col = a[:, j] - a[:, j].min()
        width = int(col.max()) + 1 if len(col) else 1
        if width * span >= _KEY_LIMIT and key is not None:
            key = _ranks(key)
            span = int(key.max()) + 1
        if width * span >= _KEY_LIMIT:
            col = _ranks(col)
            width = int(col.max()) + 1
        key = col if key is None else key * width + col
        span *= width
    return key


def _ranks(x: np.ndarray) -> np.ndarray:
    """(N,) int64 rank of each value of ``x`` among its distinct values (``np.unique``'s inverse, without its
    hash table: 10x slower than a sort on numpy 2.4)."""
    order = np.argsort(x)
    s = x[order]
    out = np.empty(len(x), np.int64)
    out[order] = np.cumsum(np.r_[False, s[1:] != s[:-1]])
    return out


def stable_order(key: np.ndarray) -> np.ndarray:
    """``np.argsort(key, kind="stable")`` of the (N,) int64 ``key`` >= 0; as one plain sort of ``key * N +
    index`` when that fits in int64 (half the time)."""
    n = len(key)
    if n and (int(key.max()) + 1) * n < _KEY_LIMIT:
        return np.sort(key * n + np.arange(n)) % n
    return np.argsort(key, kind="stable")


def unique_rows(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct rows of the (N, K) int array ``a``, numbered in order of first occurrence: the (G,) index
    of each one's first occurrence (ascending) and the (N,) group of every row."""
    if len(a) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    key = _packed_key(np.asarray(a).reshape(len(a), -1))
    order = stable_order(key)                   # stable: each group starts at its first occurrence
    s = key[order]
    starts = np.r_[True, s[1:] != s[:-1]]
    group = np.cumsum(starts) - 1
    first = order[starts]
    by_first = np.argsort(first)
    relabel = np.empty_like(by_first)
    relabel[by_first] = np.arange(len(by_first))
    inverse = np.empty(len(a), np.int64)
    inverse[order] = relabel[group]
    return first[by_first], inverse


def directed_edges(F: np.ndarray) -> np.ndarray:
    """(3F, 2) directed edges a->b in face order: face f gives rows f, F + f, 2F + f."""
    return np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])


def merged_vertex_ids(V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`unique_rows` of the (V, 3) metres ``V`` rounded to 1/:data:`MERGE_SCALE`: (first occurrence of
    each merged vertex, (V,) merged id of every vertex)."""
    return unique_rows(np.round(V * MERGE_SCALE).astype(np.int64))


def is_closed_manifold(V: np.ndarray, F: np.ndarray) -> bool:
    """True when, with vertices merged (:func:`merged_vertex_ids`), every undirected edge of the (F, 3)
    triangles belongs to exactly two of them and the two run it in opposite directions: trimesh's
    ``is_watertight and is_winding_consistent`` after ``merge_vertices`` (False for no triangles)."""
    if len(F) == 0:
        return False
    F = np.asarray(F, dtype=np.int64)
    used = np.flatnonzero(np.bincount(F.ravel(), minlength=len(V)))
    ids = np.zeros(len(V), np.int64)
    ids[used] = merged_vertex_ids(np.asarray(V, dtype=np.float64)[used])[1]  # only referenced ones, as trimesh
    E = ids[directed_edges(F)]
    n = int(ids.max()) + 1
    s = np.minimum(E[:, 0], E[:, 1])   # the undirected key (lo * n + hi), then the direction bit, in place
    s *= n
    s += np.maximum(E[:, 0], E[:, 1])
    s *= 2
    s += E[:, 0] > E[:, 1]
    del E
    s.sort()
    if len(s) % 2:
        return False
    k = s >> 1
    if not (np.array_equal(k[0::2], k[1::2]) and np.all(k[1:-1:2] != k[2::2])):
        return False                                        # some edge is not shared by exactly two faces
    # Opposite directions (trimesh compares the first edge's head with the second's tail: a loop edge a->a
    # passes).
    return bool(np.all(((s[0::2] & 1) != (s[1::2] & 1)) | (k[0::2] // n == k[0::2] % n)))
